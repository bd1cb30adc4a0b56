"""``identify`` of a floating-base robot: floating-base logs -> the identifiable combinations of one kind of rows.

:func:`symoro_gen.workflows.identify.identify` (and ``symoro-gen identify``) comes here for a robot file with
``base = "floating"``. Each log (:mod:`symoro_gen.preprocessing.floating`: its columns, and the filters: joints
band-passed as for fixed bases, the base orientation used as logged, its rates from the gyroscope or the pose) is
one experiment: its states give the standard regressor ``W`` (N, 6 + n, p) of the
:class:`~symoro_gen.runtime.floating.FloatingModel`, its torques and contact wrenches (carried by the frames'
Jacobians, :func:`~symoro_gen.identification.floating.frame_jacobian`) the right-hand sides ``Y``; both are
decimated in parallel ([GB-gains] eq. 15-16) and the samples the filters' edges reach are dropped. The
experiments' rows are stacked, reduced to the numeric rank of ``kind``'s rows and fitted by IDIM-OLS or -WLS
(:mod:`symoro_gen.identification.floating`, [AVN2014]). The statistics are the fixed-base ones ([GB-gains]
eq. 17-22); ``rel_err`` is given per row position (the 6 base-wrench rows, then each joint).
"""
from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from ..description.identity import robot_id
from ..diagnostics.candidates import CONTACT_KINDS
from ..diagnostics.core import DiagnoseSettings, diagnose
from ..diagnostics.plots import write_figures
from ..diagnostics.report import ResidualReport
from ..errors import DataFileError, OptionError, Problem
from ..identification.floating import (
    KINDS,
    ROWS,
    ContactWrench,
    FloatingIdentification,
    FloatingMeasurements,
    RowsAsJoints,
    fit_system,
    frame_jacobian,
    frame_number,
    measured_rows,
    stacked_system,
)
from ..identification.result import json_float
from ..observations.options import AssemblyOptions
from ..preprocessing.filtering import parallel_decimate
from ..preprocessing.floating import FloatingSignals, filter_floating, read_floating
from ..preprocessing.trajectory import Trajectory
from ..report.plots import MissingDependencyError
from .base import SCHEMA_VERSION, Options, Results, provenance
from .contact_candidates import ContactLog, ContactRows
from .floating_report import diagnose_figures, identify_figures, write_floating_report

__all__ = ["FloatingIdentifyResults", "FloatingDiagnoseResults", "identify_floating_logs", "diagnose_floating_logs",
           "contact_checks", "row_loop", "BASE_ROWS", "LOOP_CANDIDATES", "refused_options"]

#: the names of the 6 base-wrench rows (force, then moment about the base origin, base axes)
BASE_ROWS = ("FX0", "FY0", "FZ0", "MX0", "MY0", "MZ0")
FLOATING_METHODS = ("ols", "wls")


@dataclass(frozen=True, eq=False)
class FloatingRows:
    """One experiment's rows: ``W`` (k, 6 + n, p), ``Y`` (k, 6 + n) decimated and trimmed; the full-rate ones
    (``W_full``, ``Y_full``) for the raw-error metric; the signals they came from."""

    signals: FloatingSignals
    W: NDArray[np.float64]
    Y: NDArray[np.float64]
    W_full: NDArray[np.float64]
    Y_full: NDArray[np.float64]
    #: per contact frame, (k, 6 + n, 7) decimated with W: ``J_c^T e_i`` (a constant offset of the sensor's six
    #: components, in its axes) and ``J_c^T f_c`` (a gain error of the sensor), the candidates of :func:`contact_checks`
    sensor_columns: Mapping[str, NDArray[np.float64]] = field(default_factory=dict)
    #: the same at full rate on the rows of ``W_full`` (the loop's contact-sensor candidates, :class:`ContactRows`)
    sensor_full: Mapping[str, NDArray[np.float64]] = field(default_factory=dict)


def refused_options(opts: Any, validate_loaded: bool, loaded: Sequence) -> list[str]:
    """The ``identify`` options a floating-base robot does not take (their flags)."""
    checks = (("--loaded", bool(loaded)), ("--validate-loaded", validate_loaded or opts.validate_loaded),
              ("--payload", bool(opts.payload)), ("--gains", opts.gains is not None), ("--essential", opts.essential),
              ("--min-velocity", opts.min_velocity is not None), ("--drop-unexcited", opts.drop_unexcited),
              ("--drop-saturated", opts.drop_saturated), ("--reference", opts.reference is not None),
              ("--physical", opts.physical), ("--geometry", opts.geometry is not None),
              ("--positions motor", opts.positions != "link"), ("--validate-fraction", opts.validate_fraction is not None),
              ("data-format options (--columns, --dt, --resample...)", not opts.data_format.is_plain),
              (f"--method {opts.method}", opts.method not in FLOATING_METHODS))
    return [flag for flag, given in checks if given]


def contact_jacobian(model: Any, robot: Any, name: str, frame: int, q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Jacobian ``(N, 6, 6 + n)`` of contact frame ``frame`` in its own axes (Pinocchio's ``LOCAL``): the
    model's emitted kernel when the robot file declares the frame in ``contacts`` (a generated package or
    :class:`~symoro_gen.runtime.floating.FloatingModel`), else the MDH forward kinematics of
    :func:`~symoro_gen.identification.floating.frame_jacobian` (the same matrix; the LOCAL Jacobian does not
    depend on the base's pose)."""
    declared = tuple(getattr(model, "CONTACT_FRAMES", ()))
    for key in (name, f"frame{frame}"):
        if key in declared:
            return np.asarray(model.frame_jacobian(key, q), float).reshape(len(q), 6, -1)
    return frame_jacobian(robot, q[:, 7:], frame)[1]


def experiment_rows(model: Any, robot: Any, sig: FloatingSignals, need_tau: bool) -> FloatingRows:
    """``W``, ``Y`` of one filtered recording, decimated in parallel and trimmed (module docstring)."""
    rec, st = sig.recording, sig.settings
    contacts = []
    sensor = []
    for name, wrench in rec.contacts.items():
        try:
            j = frame_number(robot, name)
        except ValueError as exc:
            raise DataFileError([Problem(rec.source, "header", f"{name}_fx", str(exc))]) from None
        J = contact_jacobian(model, robot, name, j, sig.q)
        contacts.append(ContactWrench(name, wrench, jacobian=J))
        Jt = np.transpose(J, (0, 2, 1))  # (N, 6 + n, 6): J^T e_i, then J^T f
        sensor.append(np.concatenate([Jt, np.einsum("kir,kr->ki", Jt, wrench)[:, :, None]], axis=2))
    meas = FloatingMeasurements(sig.q, sig.dq, sig.ddq, tau=rec.tau, contacts=tuple(contacts))
    try:
        Y = measured_rows(model, meas, need_tau)
    except ValueError as exc:
        raise DataFileError([Problem(rec.source, "header", "tau1", str(exc))]) from None
    W = model.standard_regressor(sig.q, sig.dq, sig.ddq)
    p = W.shape[2]
    if sensor:
        W = np.concatenate([W, *sensor], axis=2)
    Yd, Wd = parallel_decimate(Y, W, st.n_d, ftype=st.ftype, cutoff_ratio=st.cutoff_ratio, source=rec.source)
    cols = {name: Wd[:, :, p + 7 * k:p + 7 * (k + 1)] for k, name in enumerate(rec.contacts)}
    N, e = rec.n_samples, sig.settings.edge_samples
    full = {name: W[e:N - e, :, p + 7 * k:p + 7 * (k + 1)] for k, name in enumerate(rec.contacts)}
    Wd, W = Wd[:, :, :p], W[:, :, :p]
    idx = np.arange(Yd.shape[0]) * st.n_d
    half = 10 * st.n_d if st.n_d > 1 else 0  # the FIR's half length (20 n_d + 1 taps); IIR: the edges only
    keep = (idx - half >= st.edge_samples) & (idx + half <= N - 1 - st.edge_samples)
    if not keep.any():
        raise DataFileError([Problem(rec.source, f"rows 1-{N}", "", f"too short to filter and decimate: {N} samples, "
                                     f"{st.edge_samples} dropped at each edge (cut-off {st.cutoff_hz:.4g} Hz, "
                                     f"n_d = {st.n_d})")])
    return FloatingRows(sig, Wd[keep], Yd[keep], W[e:N - e], Y[e:N - e], {c: v[keep] for c, v in cols.items()},
                        full)


def _read(model: Any, robot: Any, files: Sequence, opts: Any, need_tau: bool) -> list[FloatingRows]:
    out: list[FloatingRows] = []
    probs: list[Problem] = []
    for f in files:
        if not isinstance(f, (str, os.PathLike)):
            raise OptionError(f"identify: a floating-base robot's data are log files (docs/floating-base.md), got "
                              f"{type(f).__name__}")
        try:
            rec = read_floating(f, model.N_JOINTS)
            sig = filter_floating(rec, robot.gravity, cutoff_hz=opts.cutoff, n_d=opts.decimate)
            out.append(experiment_rows(model, robot, sig, need_tau))
        except DataFileError as exc:
            probs.extend(exc.problems)
    if probs:
        raise DataFileError(probs)
    return out


def _rel_err(Y: NDArray[np.float64], Yhat: NDArray[np.float64]) -> list[float]:
    num, den = np.linalg.norm(Y - Yhat, axis=0), np.linalg.norm(Y, axis=0)
    return [float(a / b) if b > 0 else float("nan") for a, b in zip(num, den)]


def predicted_rows(fit: FloatingIdentification, rows: Sequence[FloatingRows], sel: slice
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The measured rows ``Y`` (k, m) of the row positions ``sel`` of the decimated system and the model's
    ``W chi`` with the identified combinations (the rows :func:`_errors` compares)."""
    W = np.concatenate([r.W[:, sel][:, :, fit.columns] for r in rows])
    Y = np.concatenate([r.Y[:, sel] for r in rows])
    Yhat: NDArray[np.float64] = W @ fit.result.values
    return Y, Yhat


def _errors(fit: FloatingIdentification, rows: Sequence[FloatingRows], sel: slice) -> tuple[list[float], list[float]]:
    """Per row position: the relative error norm on the decimated rows and on the full-rate (raw) rows."""
    cols, x = fit.columns, fit.result.values
    W = np.concatenate([r.W[:, sel][:, :, cols] for r in rows])
    Y = np.concatenate([r.Y[:, sel] for r in rows])
    Wf = np.concatenate([r.W_full[:, sel][:, :, cols] for r in rows])
    Yf = np.concatenate([r.Y_full[:, sel] for r in rows])
    return _rel_err(Y, W @ x), _rel_err(Yf, Wf @ x)


def error_basis(rows: Sequence[FloatingRows], row_names: Sequence[str]) -> dict:
    """``rel_err_basis`` of the JSON (the fixed-base keys): what the two relative errors are computed on."""
    return {"rel_err": "per row position (" + " ".join(row_names) + "): ||rho||/||Y|| on the filtered, decimated "
                       "system (W and the measured rows decimated in parallel)",
            "rel_err_raw": "per row position: the model at full rate on the filtered states against the raw measured "
                           "rows (joint torques and contact wrenches carried by the frames' Jacobians)",
            "cutoff_hz": [r.signals.settings.cutoff_hz for r in rows], "n_d": [r.signals.settings.n_d for r in rows],
            "min_velocity": None, "rows": int(sum(r.Y.shape[0] for r in rows)),
            "samples": int(sum(r.Y_full.shape[0] for r in rows))}


@dataclass(frozen=True, eq=False)
class FloatingIdentifyResults(Results):
    """What ``identify`` found for a floating-base robot (see :meth:`to_dict`, docs/json-output.md)."""

    command = "identify"

    robot: Any
    model: Any
    options: Options
    fit: FloatingIdentification
    kind: str
    weighting: str
    rows: tuple[FloatingRows, ...]
    row_names: tuple[str, ...]
    rel_err: tuple[list[float], list[float]]
    validation: Mapping[str, Any] | None
    inputs: tuple[Any, ...]

    @property
    def result(self) -> Any:
        """The fixed-base :class:`~symoro_gen.identification.result.IdentificationResult` of the fit."""
        return self.fit.result

    def combinations(self, chi_std: Any) -> NDArray[np.float64]:
        """``K @ chi_std``: what the identified values estimate."""
        return self.fit.combinations(chi_std)

    def files(self) -> list[dict]:
        """Per identification log: what was read and how it was filtered (``floating.files`` of the JSON)."""
        out = []
        for r in self.rows:
            s, st = r.signals, r.signals.settings
            out.append({"file": s.recording.source, "rows_read": s.recording.n_samples, "rows": int(r.Y.shape[0]),
                        "contacts": list(s.recording.contacts), "torques": s.recording.tau is not None,
                        "orientation": s.orientation, "acceleration": s.acceleration, "cutoff_hz": st.cutoff_hz,
                        "n_d": st.n_d, "edge_samples": st.edge_samples, "unused": list(s.recording.unused)})
        return out

    def to_dict(self) -> dict:
        """Exactly the JSON of ``symoro-gen identify --json`` for a floating-base robot: the fixed-base keys
        (``rel_err`` and ``rel_err_raw`` per row position) and ``floating``."""
        res = self.fit.result
        out: dict[str, Any] = {"generator": "symoro-gen identify", "schema_version": SCHEMA_VERSION,
                               "robot": self.robot.name, "robot_id": robot_id(self.robot),
                               "data": [r.signals.recording.source for r in self.rows], "loaded": []}
        out.update(res.to_dict())
        out["rel_err"] = [json_float(v) for v in self.rel_err[0]]
        out["rel_err_raw"] = [json_float(v) for v in self.rel_err[1]]
        out["rel_err_basis"] = error_basis(self.rows, self.row_names)
        K = self.fit.relations
        out["floating"] = {
            "kind": self.kind, "weighting": self.weighting, "rows": list(self.row_names),
            "not_identifiable": list(self.fit.not_identifiable),
            "standard_names": list(self.model.STANDARD_NAMES),
            "relations": [[json_float(v) for v in row] for row in K],
            "files": self.files()}
        if self.validation is not None:
            v = self.validation
            out["validation"] = {"data": list(v["data"]), "rel_err": [json_float(x) for x in v["rel_err"]],
                                 "rel_err_raw": [json_float(x) for x in v["rel_err_raw"]],
                                 "rel_err_basis": error_basis(v["rows"], self.row_names)}
        out["provenance"] = provenance(self.options, self.inputs)
        return out

    def _fit_text(self) -> str:
        """The fixed-base fit's text, its per-group errors named by row group (kind or row position), not joint."""
        if self.weighting == "row":
            groups = list(self.row_names)
        else:
            groups = [g for g, on in (("base rows", self.kind != "joints"), ("joint rows", self.kind != "base")) if on]
        text = self.fit.result.summary()
        for k, g in enumerate(groups):
            text = text.replace(f"joint {k + 1}: ", f"{g}: ")
        return text

    def summary(self) -> str:
        """Exactly the text ``symoro-gen identify`` prints for a floating-base robot."""
        res = self.fit.result
        head = (f"Floating-base identification of {self.robot.name}: the {self.kind} rows "
                f"({' '.join(self.row_names)}), {len(res.names)} identifiable combinations of the "
                f"{len(self.model.STANDARD_NAMES)} standard parameters (the values estimate K chi_std; "
                f"floating.relations in the JSON)")
        lines = [head, "", self._fit_text(), ""]
        if self.fit.not_identifiable:
            lines.append("Not identifiable from these rows: " + " ".join(self.fit.not_identifiable))
        lines.append("Relative error norm per row (" + " ".join(self.row_names) + "):")
        lines.append("  filtered, decimated: " + "  ".join(f"{x:.4f}" for x in self.rel_err[0]))
        lines.append("  raw, full rate:      " + "  ".join(f"{x:.4f}" for x in self.rel_err[1]))
        if self.validation is not None:
            lines.append("Validation (" + ", ".join(map(str, self.validation["data"])) + "):")
            lines.append("  filtered, decimated: " + "  ".join(f"{x:.4f}" for x in self.validation["rel_err"]))
            lines.append("  raw, full rate:      " + "  ".join(f"{x:.4f}" for x in self.validation["rel_err_raw"]))
        lines.append("")
        lines.append("Data (floating-base logs):")
        for f in self.files():
            lines.append(f"  {f['file']}: {f['rows_read']} samples -> {f['rows']} rows; contacts "
                         f"{', '.join(f['contacts']) or 'none'}; torques {'yes' if f['torques'] else 'no'}; base rates "
                         f"from the {f['orientation']}, acceleration from the {f['acceleration']}; cut-off "
                         f"{f['cutoff_hz']:.4g} Hz, n_d = {f['n_d']}, {f['edge_samples']} edge samples dropped"
                         + (f"; unused columns {', '.join(f['unused'])}" if f["unused"] else ""))
        return "\n".join(lines)

    def row_predictions(self, validation: bool = False) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(Y, W chi)`` (k, rows identified) on the decimated rows of the identification logs, or of the
        validation logs with ``validation`` (:func:`predicted_rows`)."""
        if validation and self.validation is None:
            raise OptionError("row_predictions(validation=True): this result has no validation logs")
        rows = self.validation["rows"] if validation and self.validation is not None else self.rows
        return predicted_rows(self.fit, rows, ROWS[self.kind])

    def figures(self) -> list:
        """Each row's measured and modelled values (on the validation logs when given), the relative error per
        row, the combinations with 2 sigma bars (:func:`~symoro_gen.workflows.floating_report.identify_figures`)."""
        return [f.figure for f in identify_figures(self)]

    def report(self, path: Any, *, force: bool = False) -> Path:
        """The summary, the errors per row, the combinations with their standard deviations and the figures,
        ``.html`` or ``.md`` (:func:`~symoro_gen.workflows.floating_report.identify_report`)."""
        return write_floating_report(path, self, force=force)


def identify_floating_logs(robot: Any, model: Any, data: Sequence, validate: Sequence, opts: Any
                           ) -> FloatingIdentifyResults:
    """The floating-base branch of :func:`symoro_gen.workflows.identify.identify` (module docstring).

    ``opts.kind``: ``"base"``, ``"joints"`` or ``"both"`` (default: ``"both"`` when every log has joint torques,
    else ``"base"``); ``opts.weighting``: WLS groups (``"kind"`` or ``"row"``)."""
    kind = opts.kind
    if kind is not None and kind not in KINDS:
        raise OptionError(f"--kind {kind!r}: one of {', '.join(KINDS)}")
    rows = _read(model, robot, data, opts, need_tau=kind in ("joints", "both"))
    if kind is None:
        kind = "both" if all(r.signals.recording.tau is not None for r in rows) else "base"
    sel = ROWS[kind]
    W = np.concatenate([r.W for r in rows])
    Y = np.concatenate([r.Y for r in rows])
    band = min(r.signals.settings.cutoff_ratio if r.signals.settings.n_d > 1 else 1.0 for r in rows)
    fit = fit_system(model, stacked_system(model, W, Y, kind, opts.weighting), opts.method, band)
    names = (*BASE_ROWS, *(f"tau{j + 1}" for j in range(model.N_JOINTS)))[sel]
    validation = None
    if validate:
        vrows = _read(model, robot, validate, opts, need_tau=kind != "base")
        e, e_raw = _errors(fit, vrows, sel)
        validation = {"data": [str(v) for v in validate], "rel_err": e, "rel_err_raw": e_raw, "rows": tuple(vrows)}
    return FloatingIdentifyResults(robot, model, opts, fit, kind, opts.weighting, tuple(rows), tuple(names),
                                   _errors(fit, rows, sel), validation, (*data, *validate))


# ---- the loop on floating systems: contact-sensor offsets and gains, per kind of rows ---------------------------------
def _rank(A: NDArray[np.float64]) -> int:
    s = np.linalg.svd(A, compute_uv=False)
    return int(np.sum(s > s[0] * max(A.shape) * np.finfo(float).eps * 1e3)) if s.size else 0


def _stack(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """(k, rows, c) -> (rows * k, c): rows grouped by row position, as :func:`stacked_system` stacks them."""
    out: NDArray[np.float64] = x.transpose(1, 0, 2).reshape(-1, x.shape[2])
    return out


def _candidate(A: NDArray[np.float64], y: NDArray[np.float64], C: NDArray[np.float64], rss0: float,
               r0: int, band: float = 1.0) -> dict[str, Any]:
    """Nested least squares: ``y ~ A`` against ``y ~ [A C]``; the F test of the added columns ([GB-gains] eq.
    17-19 statistics, Seber & Lee 2003 sec. 4.3 for the F test) and their estimates.

    ``band``: the share of the decimated band the decimation filter passes (``cutoff_ratio``, 0.8; 1 without
    decimation). White noise decimated so has its spectrum flat over that share only, so the residual variance
    is ``band`` times the level the slow columns see: the F statistic is multiplied, the covariance divided, by it."""
    A1 = np.hstack([A, C])
    r1 = _rank(A1)
    m = C.shape[1]
    if r1 - r0 < m:
        return {"identifiable": False, "reason": f"{m - (r1 - r0)} of its {m} column(s) lie in the span of the "
                "inertial columns: a scale or an offset the parameters absorb (e.g. the gain of a contact that "
                "carries the whole wrench)"}
    x, *_ = np.linalg.lstsq(A1, y, rcond=None)
    res = y - A1 @ x
    dof = y.size - r1
    rss1 = float(res @ res)
    F = band * ((rss0 - rss1) / m) / (rss1 / dof)
    cov = rss1 / dof / band * np.linalg.pinv(A1.T @ A1)
    est = x[A.shape[1]:]
    std = np.sqrt(np.diag(cov)[A.shape[1]:])
    return {"identifiable": True, "F": float(F), "p_value": float(stats.f.sf(F, m, dof)),
            "estimate": [float(v) for v in est], "std": [float(v) for v in std],
            "rss_drop_pct": float(100 * (rss0 - rss1) / rss0) if rss0 > 0 else 0.0}


def contact_checks(model: Any, rows: Sequence[FloatingRows], kind: str, significance: float) -> list[dict[str, Any]]:
    """Per contact frame, on the rows of ``kind``: a constant offset of its sensor (6 components, in its axes) and
    a gain error (one scale of its 6 components), tested by nested F tests in forward selection (the loop's rule:
    the most significant candidate below ``significance / number of candidates`` (Bonferroni) is accepted, its
    columns added, the others tested again; stop when none is).

    An offset ``o`` (``f_measured = f + o``) adds ``J_c^T o`` to the rows; a gain ``g`` (``f_measured = (1 + g) f``)
    adds ``gamma J_c^T f_measured`` with ``gamma = g / (1 + g)``; ``estimate`` is ``o`` (N, N m) or ``g``, as last
    tested (for an accepted one: from the last fit, with every accepted effect). Each entry has ``accepted`` and
    ``round`` (the round it was accepted in, 1-based, or None). On the base rows the gains are relative: their sum
    is the measured base wrench, a common scale of all sensors is the inertial parameters' scale."""
    if kind not in ("base", "joints"):
        raise OptionError(f"contact checks run on one kind of rows: base or joints, not {kind!r}")
    sel = ROWS[kind]
    W = np.concatenate([r.W for r in rows])
    Y = np.concatenate([r.Y for r in rows])
    fs = stacked_system(model, W, Y, kind, "kind")
    A, y = fs.system.W, fs.system.Y
    cands: list[tuple[dict[str, Any], NDArray[np.float64]]] = []
    for frame in rows[0].sensor_columns:
        C = _stack(np.concatenate([r.sensor_columns[frame][:, sel, :] for r in rows]))
        for effect, cols in (("offset", slice(0, 6)), ("gain", slice(6, 7))):
            cands.append(({"kind": kind, "frame": frame, "effect": effect, "accepted": False, "round": None,
                           "components": ["fx", "fy", "fz", "mx", "my", "mz"] if effect == "offset" else ["g"]},
                          C[:, cols]))
    level = significance / max(len(cands), 1)
    band = min(r.signals.settings.cutoff_ratio if r.signals.settings.n_d > 1 else 1.0 for r in rows)
    done = False
    rnd = 0
    while not done:
        x0, *_ = np.linalg.lstsq(A, y, rcond=None)
        rss0, r0 = float(np.sum((y - A @ x0) ** 2)), _rank(A)
        best: tuple[dict[str, Any], NDArray[np.float64]] | None = None
        gains_left = [e for e, _ in cands if e["effect"] == "gain" and not e["accepted"]]
        for entry, C in cands:
            if entry["accepted"]:
                continue
            if kind == "base" and entry["effect"] == "gain" and len(gains_left) == 1:
                # the base rows are the sum of the contact wrenches: a common scale of every sensor is the
                # inertial parameters' scale, so the gains are relative and the last one is not identifiable
                entry.update(identifiable=False, reason="the base rows see the sensors' gains relative to each "
                             "other only (a common scale is the parameters' scale): the other gains are accepted")
                continue
            entry.update(_candidate(A, y, C, rss0, r0, band))
            if entry["identifiable"] and entry["effect"] == "gain":
                gam, sg = entry["estimate"][0], entry["std"][0]
                entry["estimate"], entry["std"] = [gam / (1 - gam)], [sg / (1 - gam) ** 2]
            if entry["identifiable"] and entry["p_value"] < level and (
                    best is None or entry["p_value"] < best[0]["p_value"]):
                best = (entry, C)
        done = best is None
        if best is not None:
            rnd += 1
            best[0]["accepted"], best[0]["round"] = True, rnd
            A = np.hstack([A, best[1]])
    _final_estimates([(e, C) for e, C in cands if e["accepted"]], A, y, band)
    return [e for e, _ in cands]


def _final_estimates(accepted: list, A: NDArray[np.float64], y: NDArray[np.float64], band: float) -> None:
    """The accepted effects' estimates and standard deviations from the last fit, with all of them (the
    accepted columns are the last of ``A``, in order)."""
    if not accepted:
        return
    x, *_ = np.linalg.lstsq(A, y, rcond=None)
    res = y - A @ x
    cov = float(res @ res) / (y.size - _rank(A)) / band * np.linalg.pinv(A.T @ A)
    k = A.shape[1] - sum(C.shape[1] for _, C in accepted)
    for entry, C in accepted:
        m = C.shape[1]
        est, std = x[k:k + m], np.sqrt(np.diag(cov)[k:k + m])
        if entry["effect"] == "gain":
            est, std = est / (1 - est), std / (1 - est) ** 2
        entry["estimate"], entry["std"] = [float(v) for v in est], [float(v) for v in std]
        k += m


#: the fixed-base loop's candidate kinds offered on a floating robot's joint rows (besides the friction-law stage
#: and the ``unexplained`` check): those of a drive, whose signals the joint rows have (docs/floating-base.md)
LOOP_CANDIDATES = ("stribeck", "position_ripple", "time_delay", "gain", "offset")
#: the base coordinates of the loop's signals (:class:`~symoro_gen.identification.floating.RowsAsJoints`)
BASE_SIGNALS = ("x", "y", "z", "rx", "ry", "rz")


def row_trajectories(rows: Sequence[FloatingRows]) -> list[Trajectory]:
    """Each log as a fixed-base :class:`~symoro_gen.preprocessing.trajectory.Trajectory` of the ``6 + n`` rows
    (:class:`~symoro_gen.identification.floating.RowsAsJoints`): the filtered states as recorded derivatives
    (the base's rates come from the IMU or the pose, not from differentiating a position), the measured rows
    ``S^T tau + sum_c J_c^T f_c`` as the torques; the samples the floating filters' edges reach are dropped."""
    out = []
    for r in rows:
        sig = r.signals
        N, e = sig.q.shape[0], sig.settings.edge_samples
        keep = slice(e, N - e)
        out.append(Trajectory(t=sig.recording.t[keep], q=RowsAsJoints.signals(sig.q[keep]), tau=r.Y_full,
                              dq=sig.dq[keep], ddq=sig.ddq[keep], source=sig.recording.source))
    return out


def row_loop(robot: Any, model: Any, rows: Sequence[FloatingRows], significance: float,
             seed: int = 0) -> tuple[RowsAsJoints, ResidualReport]:
    """The fixed-base loop (:func:`symoro_gen.diagnostics.diagnose`) on the rows of the floating-base logs
    ``rows`` (every log with joint torques), each row position a "joint" of
    :class:`~symoro_gen.identification.floating.RowsAsJoints`: the friction-law stage and the candidates of
    :data:`LOOP_CANDIDATES` on the joint rows, each contact sensor's offset and gain on the rows its wrench
    reaches (:class:`~symoro_gen.workflows.contact_candidates.ContactRows`, in the same rounds: sensor and drive
    explanations compete), the ``unexplained`` check on every row (the base-wrench rows included), the same
    acceptance (the last share of each log, never the validation data) and plausibility.
    The ``unexplained`` check tests the per-row weighted refit's residual (``unexplained_weighted``): the
    base-wrench rows' noise (contact sensors, and the IMU's through the base's columns) is 10 to 40 times the
    quiet joint rows' in variance, and the unweighted fit's error would leave a smooth ``-A_k delta`` on those.

    The logs' filtered states are the recorded derivatives of the assembly (no second filter), decimated with
    the floating filters' ``n_d`` and cut-off ([GB-gains] eq. 15-16)."""
    logs = [ContactLog(r.signals.recording.source, r.signals.recording.t[
        r.signals.settings.edge_samples:r.signals.q.shape[0] - r.signals.settings.edge_samples], r.sensor_full)
        for r in rows]
    adapter = ContactRows.with_contacts(RowsAsJoints.of(model, robot, np.concatenate([r.W for r in rows])), logs)
    st = [r.signals.settings for r in rows]
    assembly = AssemblyOptions(use_recorded_derivatives=True, cutoff_hz=min(s.cutoff_hz for s in st),
                               n_d=min(s.n_d for s in st), ftype=st[0].ftype, cutoff_ratio=st[0].cutoff_ratio,
                               dynamics_bandwidth_hz=max(s.dynamics_bandwidth_hz for s in st))
    cfg = DiagnoseSettings(candidates=LOOP_CANDIDATES, significance=significance, friction_laws=True,
                           composed=False, effect_joints=tuple(range(6, 6 + model.N_JOINTS)),
                           unexplained_weighted=True)
    report = diagnose(adapter, row_trajectories(rows), cfg, rng=np.random.default_rng(seed), assembly=assembly)
    return adapter, report


def row_name(i: int) -> str:
    """The name of row position ``i`` (0-based) of the ``6 + n`` rows: a base-wrench row or ``tau<j>``."""
    return BASE_ROWS[i] if i < 6 else f"tau{i - 5}"


def signal_name(name: str) -> str:
    """A signal of the loop's rows (``q3``, ``ddq8``, ``tau_hat9``...) named on the floating robot: a base
    coordinate (``q[rz]``, ``dq[x]`` the base velocity in base axes) or a joint's (``q2`` of joint 2)."""
    stem = name.rstrip("0123456789")
    k = name[len(stem):]
    if not k or stem.startswith("tau"):
        return name if not k else f"{stem}[{row_name(int(k) - 1)}]"
    k_ = int(k)
    return f"{stem}[{BASE_SIGNALS[k_ - 1]}]" if k_ <= 6 else f"{stem}{k_ - 6}"


def loop_dict(report: ResidualReport) -> dict[str, Any]:
    """``floating.loop`` of the diagnose JSON: per row position, the effects the fixed-base loop named and the
    ``unexplained`` check (docs/json-output.md)."""
    rows = [row_name(i) for i in range(report.n_joints)]
    effects = []
    for e in report.effects:
        d = e.to_dict()
        d["row"] = row_name(e.joint) if e.joint is not None else None
        if e.kind in CONTACT_KINDS:   # a contact sensor's effect: on every row its wrench reaches
            d["frame"] = e.variant
        effects.append(d)
    unexplained = [{"row": row_name(u.joint - 1), "share": json_float(u.share),
                    "threshold": json_float(u.threshold), "flagged": bool(u.flagged),
                    "signals": [signal_name(x) for x in u.signals]} for u in report.unexplained]
    return {"rows": rows, "effects": effects, "unexplained": unexplained,
            "found": [f"{d.get('frame') or d['row']}:{d['kind']}" for d in effects],
            "rel_err_before": [json_float(v) for v in report.before_validation_rel_err],
            "rel_err_after": [json_float(v) for v in report.after_validation_rel_err],
            "acceptance": "the last share of each log (held out from the fits of the candidates); the validation "
                          "errors are those of the last share of each log, held out from the final fit",
            "warnings": list(report.warnings)}


def _loop_lines(loop: Mapping[str, Any] | None, note: str) -> list[str]:
    if loop is None:
        return ["", f"Residual analysis per row (the fixed-base loop): not run: {note}"]
    lines = ["", "Residual analysis per row (the fixed-base loop on the base-wrench and joint rows: friction law, "
             + ", ".join(LOOP_CANDIDATES) + " on the joint rows; each contact sensor's offset and gain on the rows its "
             "wrench reaches, in the same selection; unexplained structure on every row):"]
    for d in loop["effects"]:
        vals = ", ".join(f"{n} {v:+.4g} +- {d['std'][n]:.2g}" for n, v in d["params"].items() if v is not None
                         and d["std"].get(n) is not None)
        where = d["row"] or f"sensor {d.get('frame')}"
        lines.append(f"  {where:6s} {d['label']} (round {d['round']}, verdict {d['verdict'] or '-'}): {vals}")
    flagged = [u for u in loop["unexplained"] if u["flagged"]]
    for u in flagged:
        lines.append(f"  {u['row']:6s} unexplained structure: out-of-fold R^2 {u['share']:.3f} > {u['threshold']:.3f}"
                     + (f" (signals {', '.join(u['signals'][:4])})" if u["signals"] else ""))
    if not loop["effects"] and not flagged:
        lines.append("  nothing beyond the noise on any row")
    lines.append("  validation rel. error per row before -> after: " + "  ".join(
        f"{r} {a:.4f}->{b:.4f}" for r, a, b in zip(loop["rows"], loop["rel_err_before"], loop["rel_err_after"])
        if a is not None and b is not None))
    return lines


@dataclass(frozen=True, eq=False)
class FloatingDiagnoseResults(Results):
    """``diagnose`` of a floating-base robot: the contact-sensor checks per kind of rows (docs/floating-base.md)."""

    command = "diagnose"

    robot: Any
    model: Any
    options: Options
    rows: tuple[FloatingRows, ...]
    checks: tuple[dict[str, Any], ...]
    significance: float
    inputs: tuple[Any, ...]
    #: ``floating.loop`` of the JSON (:func:`loop_dict`), None when the loop did not run (``loop_note`` says why)
    loop: Mapping[str, Any] | None = None
    loop_note: str = ""
    #: the fixed-base loop's report on the rows (the joint numbers are row positions, 0-5 the base rows)
    loop_report: ResidualReport | None = None

    @property
    def found(self) -> list[dict[str, Any]]:
        """The accepted checks, per kind in the order of acceptance."""
        return [c for c in self.checks if c["accepted"]]

    def to_dict(self) -> dict:
        """The JSON of ``symoro-gen diagnose --json`` for a floating-base robot (docs/json-output.md)."""
        n = sum(1 for c in self.checks if c["kind"] == "base")
        return {"generator": "symoro-gen diagnose", "schema_version": SCHEMA_VERSION, "robot": self.robot.name,
                "robot_id": robot_id(self.robot), "data": [r.signals.recording.source for r in self.rows],
                "floating": {"significance": self.significance, "level": self.significance / max(n, 1),
                             "checks": [{k: (json_float(v) if isinstance(v, float) else v) for k, v in c.items()}
                                        for c in self.checks],
                             "found": [f"{c['kind']}:{c['frame']}:{c['effect']}" for c in self.found],
                             "loop": self.loop, "loop_note": self.loop_note or None},
                "provenance": provenance(self.options, self.inputs)}

    def summary(self) -> str:
        """The text ``symoro-gen diagnose`` prints for a floating-base robot."""
        n = sum(1 for c in self.checks if c["kind"] == "base")
        if self.loop is not None:   # the sensors are candidates of the loop's own selection
            return "\n".join([f"Diagnosis of {self.robot.name} (floating base): the contact sensors' offsets and gains "
                              "compete with the drive effects in the loop's selection below",
                              *_loop_lines(self.loop, self.loop_note)])
        lines = [f"Contact-sensor checks of {self.robot.name} (per kind of rows: an offset of each sensor's six "
                 f"components, a gain of each sensor; nested F tests in forward selection, level "
                 f"{self.significance:g} / {n} candidates = {self.significance / max(n, 1):.3g}):"]
        for c in self.checks:
            head = f"  {c['kind']:6s} {c['frame']:>10s} {c['effect']:6s}"
            if not c["identifiable"]:
                lines.append(f"{head}  not identifiable: {c['reason']}")
                continue
            vals = ", ".join(f"{n} {v:+.4g} +- {s:.2g}" for n, v, s in zip(c["components"], c["estimate"], c["std"]))
            mark = f"FOUND ({c['round']})" if c["accepted"] else "         "
            lines.append(f"{head}  {mark} p = {c['p_value']:.3g}, residual -{c['rss_drop_pct']:.2g} %: {vals}")
        found = self.found
        lines.append("")
        lines.append("Found: " + ("; ".join(f"{c['effect']} of the sensor at {c['frame']} (from the {c['kind']} rows)"
                                            for c in found) if found else "nothing beyond the noise"))
        lines += _loop_lines(self.loop, self.loop_note)
        return "\n".join(lines)

    @property
    def level(self) -> float:
        """The contact checks' Bonferroni level: ``significance`` over the number of candidates."""
        return self.significance / max(sum(1 for c in self.checks if c["kind"] == "base"), 1)

    def figures(self) -> list:
        """The validation error per row before and after the loop with the effects named per row, or the contact
        checks' p-values (:func:`~symoro_gen.workflows.floating_report.diagnose_figures`)."""
        return [f.figure for f in diagnose_figures(self)]

    def write_plots(self, folder: Any, *, force: bool = False) -> list[Path]:
        """The figures as ``diagnosis-*.png`` files in ``folder`` (``--plots``:
        :func:`~symoro_gen.diagnostics.plots.write_figures`; empty without matplotlib)."""
        try:
            figures = diagnose_figures(self)
        except MissingDependencyError:
            return []
        return write_figures(figures, folder, force=force)

    def report(self, path: Any, *, force: bool = False) -> Path:
        """The effects with their verdicts, the unexplained check, the errors per row before and after (or the
        contact checks) and the figures, ``.html`` or ``.md``
        (:func:`~symoro_gen.workflows.floating_report.diagnose_report`)."""
        return write_floating_report(path, self, force=force)


def diagnose_floating_logs(robot: Any, model: Any, data: Sequence, opts: Any) -> FloatingDiagnoseResults:
    """The floating-base branch of :func:`symoro_gen.workflows.diagnose.diagnose`: when every log has joint torques,
    the loop on the rows (:func:`row_loop`), the contact sensors' offsets and gains among its candidates; else
    :func:`contact_checks` on the base rows (the loop does not run there)."""
    rows = _read(model, robot, data, opts, need_tau=False)
    has_tau = all(r.signals.recording.tau is not None for r in rows)
    frames = [tuple(r.sensor_columns) for r in rows]
    if any(f != frames[0] for f in frames):
        raise DataFileError([Problem(r.signals.recording.source, "header", "<frame>_fx", f"contact frames "
                                     f"{', '.join(f) or 'none'}, the first log's are {', '.join(frames[0]) or 'none'}: "
                                     "diagnose checks the same sensors in every log") for r, f in zip(rows, frames)
                             if f != frames[0]])
    if not frames[0] and not has_tau:
        raise OptionError(f"diagnose: {robot.file or robot.name}: the logs have neither contact wrench columns "
                          "(<frame>_fx ...) nor joint torques (tau1 ...): nothing to check on a floating-base robot")
    checks: list[dict[str, Any]] = []
    loop: dict[str, Any] | None = None
    report: ResidualReport | None = None
    note = ""
    if has_tau:
        # the contact sensors' offsets and gains are candidates of the loop's own selection (row_loop)
        _, report = row_loop(robot, model, rows, opts.significance)
        loop = loop_dict(report)
    else:
        checks = contact_checks(model, rows, "base", opts.significance)
        note = ("the logs have no joint torques (tau1..): the base rows depend on the joints' motion, the loop "
                "analyses both kinds of rows together")
    return FloatingDiagnoseResults(robot, model, opts, tuple(rows), tuple(checks), opts.significance, tuple(data),
                                   loop, note, report)
