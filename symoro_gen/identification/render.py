"""The identification's own report blocks and HTML (Jupyter), drawn with the generic toolkit of
:mod:`symoro_gen.report`: the papers' tables (parameters with 2σ and %σ, [GB-gains] Table 3 and [LWR4-TLS]
Table II; gains, [LWR4-TLS] Table II and [GB-gains] Table 4; relative error norms, [LWR4-TLS] Table III; the
payload, [LWR4-TLS] Table IV), measured vs reconstructed torques ([LWR4-TLS] Fig. 3) and the singular values
of W. Result objects are read through their public attributes only (this module imports none of them).
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..observations.assembly import basis_text
from ..observations.system import ObservationSystem
from ..report.document import Heading, Paragraph, Table
from ..report.plots import DPI, MAX_POINTS, singular_values_figure, torque_figure
from ..report.tables import (
    fmt_known,
    fmt_pct,
    fmt_value,
    html_fragment,
    is_mass_name,
    is_poor,
    raw_err_table,
    rel_err_table,
    slug,
    warnings_block,
)

__all__ = ["IdentificationBlocks", "drive_gains_html", "drive_gains_table", "gains_html", "gains_table",
           "identification_blocks", "labelled_systems", "method_label", "parameter_table", "payload_mass_text",
           "payload_table", "reference_table", "result_blocks", "result_html", "result_overview",
           "scaled_singular_values"]


def method_label(method: str) -> str:
    """The estimator's name in headers: ``IDIM-OLS``, ``IDIM-IV``...; DIDIM is not an IDIM method
    (output error in closed loop, Gautier, Janot & Vandanjon 2013) and keeps its own name."""
    return "DIDIM" if str(method).upper() == "DIDIM" else f"IDIM-{method}"


def parameter_table(result, caption: str = "Identified parameters", names: Sequence[str] | None = None) -> Table:
    """Parameter, value, 2σ, %σ (RX-90 paper Table 3, LWR4 paper Table II); known (fixed) parameters
    marked ``known``, cancelled ones (essential parameters) ``cancelled``.

    Parameters
    ----------
    result : IdentificationResult
    names : sequence of str, optional
        Only these parameters (estimated, fixed or cancelled), in this order.
    """
    est = {n: (float(v), float(s), float(p)) for n, v, s, p in
           zip(result.names, result.values, result.std, result.rel_std_pct)}
    fixed = dict(result.fixed)
    cancelled = set(result.eliminated)
    order = list(names) if names is not None else list(result.names) + [n for n, _ in result.fixed] + list(result.eliminated)
    rows, classes = [], []
    for n in order:
        if n in est:
            v, s, p = est[n]
            rows.append((n, fmt_value(v), fmt_value(2 * s), fmt_pct(p), "poorly identified" if is_poor(p) else ""))
            classes.append("poor" if is_poor(p) else "")
        elif n in fixed:
            rows.append((n, fmt_known(fixed[n]), "-", "-", "known"))
            classes.append("")
        elif n in cancelled:
            rows.append((n, "0", "-", "-", "cancelled (essential parameters)"))
            classes.append("")
    return Table(("Parameter", "Value", "2σ", "%σ", "Note"), tuple(rows), caption,
                 numeric=(False, True, True, True, False), row_classes=tuple(classes))


def gains_table(gains, caption: str = "Gains", cond: Sequence[float] | None = None) -> Table:
    """Gain, joint, value, 2σ, %σ (LWR4 paper Table II, RX-90 paper Table 4); optional cond(W) per gain."""
    head = ["Gain", "Joint", "Value", "2σ", "%σ"] + (["cond(W)"] if cond is not None else [])
    rows, classes = [], []
    for k, (n, j, v, s, p) in enumerate(zip(gains.names, gains.joints, gains.values, gains.std, gains.rel_std_pct)):
        r = [n, str(j + 1), fmt_value(v), fmt_value(2 * s), fmt_pct(p)]
        if cond is not None:
            r.append(fmt_value(cond[k]))
        rows.append(tuple(r))
        classes.append("poor" if is_poor(p) else "")
    return Table(tuple(head), tuple(rows), caption, numeric=(False,) + (True,) * (len(head) - 1),
                 row_classes=tuple(classes))


def drive_gains_table(dg, caption: str = "Drive gains, per-joint weighted LS with a known payload (RX-90 eq. 27)") -> Table:
    return gains_table(dg.gains, caption, cond=[r.cond for r in dg.per_joint])


def payload_table(result, payload_names: Sequence[str], caption: str = "Payload parameters") -> Table | None:
    """The payload's parameters of a result (identified, known or cancelled); None when it has none."""
    have = set(result.names) | {n for n, _ in result.fixed} | set(result.eliminated)
    names = [n for n in payload_names if n in have]
    if not names:
        return None
    return parameter_table(result, caption, names=names)


def payload_mass_text(result, payload_names: Sequence[str], what: str) -> str | None:
    """``"payload mass M8 = 4.614 kg (known)"``-style sentence; None when the result has no mass."""
    fixed = dict(result.fixed)
    for n in payload_names:
        if not is_mass_name(n):
            continue
        if n in result.names:
            i = result.names.index(n)
            return (f"{what}: {n} = {fmt_value(result.values[i])} kg, 2σ = {fmt_value(2 * result.std[i])} kg, "
                    f"%σ = {fmt_pct(result.rel_std_pct[i])}")
        if n in fixed:
            return f"{what}: {n} = {fmt_known(fixed[n])} kg (known, weighed)"
    return None


def reference_table(rows, caption: str = "Beside the published reference table") -> Table:
    """Rows of :func:`symoro_gen.identification.reference.compare_with_reference`."""
    body, classes = [], []
    for r in rows:
        if r.name is None:
            body.append((r.expression, "-", "", "", fmt_value(r.ref), fmt_pct(r.ref_rel_std_pct), "not in our model"))
            classes.append("")
        else:
            body.append((r.expression, r.name, fmt_value(r.ours), fmt_pct(r.ours_rel_std_pct), fmt_value(r.ref),
                         fmt_pct(r.ref_rel_std_pct), "yes" if r.agree_2sigma else "no"))
            classes.append("" if r.agree_2sigma else "poor")
    n = sum(r.agree_2sigma is not None for r in rows)
    a = sum(bool(r.agree_2sigma) for r in rows)
    return Table(("Reference expression", "Ours", "Value", "%σ", "Reference", "%σ", "Within 2σ"), tuple(body),
                 f"{caption}: {a} of {n} comparable parameters agree within 2σ",
                 numeric=(False, False, True, True, True, True, False), row_classes=tuple(classes))


def result_overview(result) -> str:
    return (f"{method_label(result.method)}: {result.n_rows} equations, {result.n_params} parameters; "
            f"cond(W) = {fmt_value(result.cond)} (columns scaled: {fmt_value(result.cond_scaled)}); "
            f"σ = {fmt_value(result.sigma)}")


def result_blocks(result, *, heading_level: int = 3) -> list:
    """Overview line, gains, parameters, relative error norms and warnings of one result."""
    blocks: list = [Paragraph(result_overview(result))]
    if getattr(result, "gains", None) is not None:
        blocks.append(gains_table(result.gains))
    blocks.append(parameter_table(result))
    blocks.append(rel_err_table([("identification", result.rel_err)], result.n_joints))
    if getattr(result, "joint_sigma", None) is not None:
        blocks.append(Paragraph("Row weights 1/σ_j with σ_j = "
                                + ", ".join(fmt_value(s) for s in result.joint_sigma)))
    blocks += warnings_block(result.warnings)
    return blocks


def result_html(result) -> str:
    """HTML tables of an :class:`~symoro_gen.identification.result.IdentificationResult` (Jupyter)."""
    return html_fragment(result_blocks(result), "symoro-gen-result")


def gains_html(gains) -> str:
    """HTML table of a :class:`~symoro_gen.identification.result.Gains` (Jupyter)."""
    return html_fragment([gains_table(gains)], "symoro-gen-result")


def drive_gains_html(dg) -> str:
    """HTML of a :class:`~symoro_gen.identification.gains.DriveGainsResult` (Jupyter)."""
    return html_fragment([drive_gains_table(dg)] + warnings_block(dg.warnings), "symoro-gen-result")


def labelled_systems(systems, default: str) -> list[tuple[str, ObservationSystem]]:
    """``[(label, ObservationSystem)]`` from a mapping, a sequence of pairs or of systems, or one system."""
    if systems is None:
        return []
    if isinstance(systems, Mapping):
        return [(str(k), v) for k, v in systems.items() if v is not None]
    if hasattr(systems, "W") and hasattr(systems, "Y"):
        return [(default, systems)]
    if isinstance(systems, tuple) and len(systems) == 2 and isinstance(systems[0], str):
        return [(systems[0], systems[1])] if systems[1] is not None else []
    out = []
    items = list(systems)
    for k, s in enumerate(items):
        if isinstance(s, tuple) and len(s) == 2:
            if s[1] is not None:
                out.append((str(s[0]), s[1]))
        elif s is not None:
            out.append((default if len(items) == 1 else f"{default} {k + 1}", s))
    return out


def scaled_singular_values(systems: Sequence, names: Sequence[str]) -> np.ndarray:
    """Singular values of the stacked observation matrix of ``systems`` restricted to the columns
    ``names`` (zero where a system lacks one), each column scaled to unit norm, rows unweighted.

    Parameters
    ----------
    systems : sequence of ObservationSystem
    names : sequence of str

    Returns
    -------
    ndarray, shape (len(names),)
        Largest first; ``s[0] / s[-1]`` is the column-scaled condition number.
    """
    blocks = []
    for s in systems:
        col = {n: i for i, n in enumerate(s.names)}
        B = np.zeros((s.W.shape[0], len(names)))
        for k, n in enumerate(names):
            if n in col:
                B[:, k] = s.W[:, col[n]]
        blocks.append(B)
    W = np.vstack(blocks)
    norms = np.linalg.norm(W, axis=0)
    norms[norms == 0] = 1.0
    W = W / norms
    if W.shape[0] > W.shape[1]:
        W = np.asarray(np.linalg.qr(W, mode="r"))
    return np.linalg.svd(W, compute_uv=False)


def _payload_names(result, ident, payload_names):
    if payload_names is not None:
        return tuple(payload_names)
    if len(ident) < 2:
        return ()
    sets = [set(s.names) for _, s in ident]
    common = set.intersection(*sets)
    return tuple(n for n in dict.fromkeys(n for _, s in ident for n in s.names) if n not in common)


def _can_predict(result, system) -> bool:
    pm = result.parameter_map()
    return all(n in pm for n in system.names)


@dataclass(frozen=True, eq=False)
class IdentificationBlocks:
    """What a report shows of an identification besides its result.

    Attributes
    ----------
    identification, validation : ObservationSystem, or sequence of them or of (label, system), or mapping
        Systems the torques are reconstructed on (measured vs reconstructed per joint, [LWR4-TLS] Fig. 3) and
        whose relative error norms are tabulated ([LWR4-TLS] Table III); the identification systems also give
        the singular values of W.
    payload_names : sequence of str, optional
        The payload's parameters (default: the columns not common to every identification system).
    payload : IdentificationResult, optional
        Payload re-identified with the robot known ([LWR4-TLS] Table IV).
    drive : DriveGainsResult, optional
        Per-joint drive gains ([GB-gains] Table 4), with cond(W) per joint.
    reference : sequence of ReferenceRow, optional
        :func:`~symoro_gen.identification.reference.compare_with_reference` rows.
    raw_errors : sequence of (label, errors per joint)
        Raw-torque relative error norms listed below the filtered ones (the result's own ``rel_err_raw``
        first when it has one).
    """

    identification: Any = None
    validation: Any = None
    payload_names: Sequence[str] | None = None
    payload: Any = None
    drive: Any = None
    reference: Sequence | None = None
    raw_errors: Sequence[tuple[str, Sequence[float]]] = ()


@dataclass(frozen=True, eq=False)
class IdentificationSections:
    """The identification's blocks, in the report's order: ``quality`` (errors, gains, payload) before a
    diagnosis, ``figures`` (torques, singular values) after it, ``parameters`` (parameters, reference) last;
    ``notes`` for the report's notes; ``warnings`` of the drive gains and the payload."""

    quality: list
    figures: list
    parameters: list
    notes: list
    warnings: tuple[str, ...]


def _quality_blocks(result, ident, valid, what: IdentificationBlocks) -> list:
    """Relative error norms (filtered and raw), gains, payload."""
    n = result.n_joints
    basis = basis_text(getattr(result, "rel_err_basis", None))
    rows = [("identification (as fitted)", result.rel_err)]
    if len(ident) > 1:
        rows += [(lab, result.rel_err_on(s)) for lab, s in ident if _can_predict(result, s)]
    rows += [(lab, result.rel_err_on(s)) for lab, s in valid if _can_predict(result, s)]
    raw = list(what.raw_errors)
    if getattr(result, "rel_err_raw", None) is not None:
        raw.insert(0, ("identification data", result.rel_err_raw))
    B: list = [Heading("Quality of the torque reconstruction"),
               rel_err_table(rows, n, caption=f"Relative error norms ‖ρ_j‖/‖Y_j‖ per joint on the {basis}")]
    if raw:
        B.append(raw_err_table(raw, n))
    gains = getattr(result, "gains", None)
    if what.drive is not None or gains is not None:
        B.append(Heading("Gains"))
        if what.drive is not None:
            B.append(drive_gains_table(what.drive))
        elif gains is not None:
            B.append(gains_table(gains, "Torque-sensor gains (IDIM-TLS, LWR4 eq. 8-16)"
                                 if str(result.method).upper().startswith("TLS") else "Gains"))
    payload = what.payload
    pnames = _payload_names(result, ident, what.payload_names)
    ptab = payload_table(result, pnames) if pnames else None
    mass = [t for t in (payload_mass_text(result, pnames, "Payload mass in the identification"),
                        payload_mass_text(payload, pnames or payload.names,
                                          "Payload mass re-identified on the validation data, robot known "
                                          "(Table IV)") if payload is not None else None) if t]
    if ptab is not None or payload is not None:
        B.append(Heading("Payload"))
        B += [Paragraph(t) for t in mass]
        if ptab is not None:
            B.append(ptab)
        if payload is not None:
            B.append(parameter_table(payload, "Payload re-identified with the robot model known",
                                     names=list(payload.names)))
    return B


def _figure_blocks(result, ident, valid, max_points: int, dpi: int, notes: list) -> list:
    """Measured and reconstructed torques of every data set, singular values of the identification W."""
    B: list = []
    if ident or valid:
        B.append(Heading("Measured and reconstructed torques"))
        for group in (ident, valid):
            for lab, s in group:
                if not _can_predict(result, s):
                    notes.append(f"{lab}: columns {[c for c in s.names if c not in result.parameter_map()]} are "
                                 f"not parameters of the result: torques not reconstructed")
                    continue
                y = result.scaled_measurements(s)
                B.append(torque_figure(f"torque-{slug(lab)}",
                                       f"{lab[:1].upper() + lab[1:]}: measured"
                                       f"{' (× identified gain)' if getattr(result, 'gains', None) is not None else ''}"
                                       f" and reconstructed torque per joint",
                                       y, result.predict(s), s.joint, result.n_joints,
                                       rel_err=result.rel_err_on(s), max_points=max_points, dpi=dpi))
    est = [nm for nm in result.names if any(nm in s.names for _, s in ident)] if ident else []
    if est:
        sv = scaled_singular_values([sy for _, sy in ident], est)
        cond = sv[0] / sv[-1] if sv[-1] > 0 else math.inf
        gains = ", gain columns included" if getattr(result, "gains", None) is not None else ""
        B.append(Heading("Conditioning of the observation matrix"))
        B.append(singular_values_figure(
            "singular-values", sv,
            title=f"Singular values of W, columns scaled to unit norm: cond = {fmt_value(cond)}",
            caption=f"Singular values of the identification observation matrix W restricted to the {len(est)} "
                    f"estimated parameters, each column scaled to unit norm, rows unweighted: condition number "
                    f"{fmt_value(cond)}. As solved (rows weighted by the method{gains}): "
                    f"cond(W) = {fmt_value(result.cond)}, with unit-norm columns {fmt_value(result.cond_scaled)}.",
            dpi=dpi))
    return B


def identification_blocks(result, what: IdentificationBlocks, *, diagnosed: bool = False, plots: bool = True,
                          max_points: int = MAX_POINTS, dpi: int = DPI) -> IdentificationSections:
    """The report's blocks of an identification result (``diagnosed``: it is a diagnosis' final model)."""
    ident = labelled_systems(what.identification, "identification data")
    valid = labelled_systems(what.validation, "validation data")
    notes: list = []
    quality = _quality_blocks(result, ident, valid, what) if (ident or valid or not diagnosed) else []
    figures = _figure_blocks(result, ident, valid, max_points, dpi, notes) if plots else []
    params: list = [Heading("Parameters of the final model" if diagnosed else "Identified parameters"),
                    parameter_table(result, "Parameters: value, 2σ, %σ (= 100 σ/|value|); rows shaded: %σ > 30")]
    if getattr(result, "joint_sigma", None) is not None:
        params.append(Paragraph("Row weights 1/σ_j with σ_j = " + ", ".join(fmt_value(x) for x in result.joint_sigma)))
    if what.reference:
        params += [Heading("Reference"), reference_table(what.reference)]
    warns = tuple(getattr(what.drive, "warnings", ()) if what.drive is not None else ()) + tuple(
        getattr(what.payload, "warnings", ()) if what.payload is not None else ())
    return IdentificationSections(quality, figures, params, notes, warns)
