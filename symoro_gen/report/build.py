"""Assemble a report from identification results, observation systems and a residual diagnosis.

:func:`build_report` returns a :class:`~symoro_gen.report.document.Report` value (tables and PNG
figures); :func:`write_report` renders it to ``.html`` (self-contained) or ``.md`` (images beside it)
atomically. Inputs are read, never modified.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from .. import __version__
from ..observations.assembly import basis_text
from ..observations.system import ObservationSystem
from .document import (
    REPORT_SUFFIXES,
    Heading,
    ItemList,
    Paragraph,
    Preformatted,
    Report,
    ReportError,
    Table,
    render_html_fragment,
    report_kind,
    write_report_files,
)
from .plots import (
    DPI,
    MAX_POINTS,
    N_BINS,
    error_bars_figure,
    require_matplotlib,
    residual_figure,
    singular_values_figure,
    torque_figure,
)
from .tables import (
    drive_gains_table,
    fmt_pct,
    fmt_value,
    gains_table,
    parameter_table,
    payload_mass_text,
    payload_table,
    reference_table,
    rel_err_table,
    result_overview,
    unique_in_order,
    warnings_block,
)

__all__ = ["build_report", "write_report", "check_report_path", "diagnosis_html", "scaled_singular_values", "diagnosis_plot_series"]

#: best candidates listed per round of a diagnosis
N_CANDIDATES = 10


def _labelled(systems, default: str) -> list[tuple[str, ObservationSystem]]:
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


def _slug(text: str) -> str:
    s = "".join(c if c.isalnum() else "-" for c in text.lower())
    while "--" in s:
        s = s.replace("--", "-")
    return s.strip("-") or "figure"


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


# ---- diagnosis -------------------------------------------------------------------------------------
def diagnosis_plot_series(diagnosis) -> dict | None:
    """The arrays behind a diagnosis' residual plots, from its public objects.

    Reads ``diagnosis.plot_data`` (``frame`` and ``vframe`` with ``system`` and ``sig``,
    ``round_resid``: ``[(identification residual, validation residual)]``, before the first effect then
    after each); returns None when they are not there.

    Returns
    -------
    dict or None
        ``Y``, ``joint``, ``sig`` (identification), ``Yv``, ``jointv``, ``sigv`` (validation),
        ``rounds`` (list of (r_id, r_val)).
    """
    pd = getattr(diagnosis, "plot_data", None)
    if not isinstance(pd, Mapping):
        return None
    F, V, rr = pd.get("frame"), pd.get("vframe"), pd.get("round_resid")
    if F is None or V is None or rr is None:
        return None
    try:
        out = {"Y": np.asarray(F.system.Y), "joint": np.asarray(F.system.joint), "sig": F.sig,
               "Yv": np.asarray(V.system.Y), "jointv": np.asarray(V.system.joint), "sigv": V.sig,
               "rounds": [(np.asarray(a, float), np.asarray(b, float)) for a, b in rr]}
    except (AttributeError, TypeError, ValueError):
        return None
    if not out["rounds"] or any(a.shape != out["Y"].shape or b.shape != out["Yv"].shape for a, b in out["rounds"]):
        return None
    return out


def _signal(sig, key: str, rows: np.ndarray, joint: int) -> np.ndarray | None:
    if not isinstance(sig, Mapping) or key not in sig:
        return None
    a = np.asarray(sig[key], float)
    if a.ndim == 1:
        return a[rows]
    if a.ndim == 2 and 0 <= joint < a.shape[1]:
        return a[rows, joint]
    return None


def _signal_label(key: str) -> str:
    try:  # lazy: diagnostics imports this package (diagnostics -> report), a top-level import would be a circle
        from ..diagnostics.structure import SIGNAL_LABELS
    except ImportError:  # diagnostics not available: the key itself
        SIGNAL_LABELS = {}
    return SIGNAL_LABELS.get(key, key)


def _effect_who(e) -> str:
    who = "all joints" if e.joint is None else f"joint {e.joint + 1}"
    if getattr(e, "partner", None) is not None:
        who += f" ({e.variant}, with joint {e.partner + 1})"
    return who


def _setting(diag, key: str) -> str:
    st = diag.settings if isinstance(getattr(diag, "settings", None), Mapping) else {}
    v = st.get(key)
    return "?" if v is None else f"{float(v):.4g}"


def raw_err_table(rows, n_joints: int) -> Table:
    """Raw-torque relative error norms (``rel_err_raw``), its own table with a header saying so."""
    t = rel_err_table(rows, n_joints, caption=(
        "Relative error norms on the raw measured torque: ‖τ_j − τ̂_j‖/‖τ_j‖, the model at full rate on the "
        "filtered states against the unfiltered torque, every sample (no row selection)"))
    return Table(("Data (raw measured torque)",) + tuple(t.header[1:]), t.rows, t.caption)


def _diagnosis_blocks(diag, plots: bool, max_points: int, n_bins: int, dpi: int, notes: list) -> list:
    n = diag.n_joints
    B: list = [Heading("Residual diagnosis"),
               Paragraph(f"IDIM-{str(diag.method).upper()}; validation: "
                         f"{diag.settings.get('validation', '?') if isinstance(diag.settings, Mapping) else '?'}; "
                         f"{len(diag.effects)} effect(s) added.")]
    B.append(rel_err_table([("identification, before", diag.before_rel_err),
                            ("identification, after", diag.after_rel_err),
                            ("validation, before", diag.before_validation_rel_err),
                            ("validation, after", diag.after_validation_rel_err)], n,
                           "Relative error norms ‖ρ_j‖/‖Y_j‖ before and after the effects added, on the filtered, "
                           f"decimated system (cut-off {_setting(diag, 'cutoff_hz')} Hz, "
                           f"n_d = {_setting(diag, 'n_d')})"))
    raw_b = getattr(diag, "before_validation_rel_err_raw", None)
    raw_a = getattr(diag, "after_validation_rel_err_raw", None)
    if raw_b is not None and raw_a is not None:
        B.append(raw_err_table([("validation, before", raw_b), ("validation, after", raw_a)], n))
    if diag.effects:
        rows = []
        for i, e in enumerate(diag.effects, 1):
            params = "; ".join(f"{nm} = {fmt_value(v)} (%σ {fmt_pct(p)})"
                               for nm, v, p in zip(e.names, e.values, e.rel_std_pct))
            phys = ", ".join(f"{k} = {fmt_value(v)}" for k, v in (e.physical or {}).items())
            rows.append((str(i), e.kind, _effect_who(e), params, phys, fmt_value(e.score), f"{e.p_value:.2e}",
                         fmt_value(e.z_validation)))
        B.append(Table(("#", "Effect", "Where", "Parameters (value, %σ)", "Physical reading", "Score", "p",
                        "z_val"), tuple(rows), "Effects added, in order",
                       numeric=(True, False, False, False, False, True, True, True),
                       row_classes=("added",) * len(rows)))
    else:
        B.append(Paragraph("No effect added: no candidate was significant on the identification data and better "
                           "than noise on the validation data."))
    for r in sorted({c.round for c in diag.tried}):
        best = sorted((c for c in diag.tried if c.round == r and c.score is not None), key=lambda c: -c.score)
        best = best[:N_CANDIDATES]
        if not best:
            continue
        B.append(Table(("Candidate", "Score", "p", "Threshold", "z_val", "Verdict"),
                       tuple((c.label + (f" {c.variant}" if c.variant and c.kind != "coupling" else ""),
                              fmt_value(c.score), f"{c.p_value:.2e}" if c.p_value is not None else "-",
                              f"{c.threshold:.1e}" if c.threshold is not None else "-",
                              fmt_value(c.z_validation), "eligible" if c.eligible else c.reason) for c in best),
                       f"Round {r}: best candidates by validation score",
                       numeric=(False, True, True, True, True, False),
                       row_classes=tuple("added" if c.eligible else "" for c in best)))
    left = [s for s in getattr(diag, "structure_after", ()) if getattr(s, "significant", False)]
    if left:
        B.append(Table(("Joint", "Against", "Explained variance", "p (Bonferroni)"),
                       tuple((str(s.joint + 1), s.label, f"{100 * s.eta2:.1f} %", f"{s.p_value:.1e}")
                             for s in sorted(left, key=lambda s: -s.eta2)[:12]),
                       "Structure left in the identification residual",
                       numeric=(True, False, True, True)))
    if not plots:
        return B
    B.append(error_bars_figure("diagnosis-errors", "Relative error norms per joint, before and after",
                               [("identification, before", diag.before_rel_err),
                                ("identification, after", diag.after_rel_err),
                                ("validation, before", diag.before_validation_rel_err),
                                ("validation, after", diag.after_validation_rel_err)], dpi=dpi))
    ser = diagnosis_plot_series(diag)
    if ser is None:
        notes.append("residual plots of the diagnosis are not available (the diagnosis carries no plot data)")
        return B
    for i, e in enumerate(diag.effects, 1):
        k = int(getattr(e, "round", i))
        if not (1 <= k < len(ser["rounds"])):
            notes.append(f"effect {i} ({e.kind}): no residual of round {k} in the plot data")
            continue
        (rb, rvb), (ra, rva) = ser["rounds"][k - 1], ser["rounds"][k]
        j = e.joint
        if j is None:  # effect on all joints: show the joint whose identification residual dropped most
            nb = np.bincount(ser["joint"], rb ** 2, n)
            na = np.bincount(ser["joint"], ra ** 2, n)
            with np.errstate(divide="ignore", invalid="ignore"):
                j = int(np.nanargmax(np.where(nb > 0, (nb - na) / nb, -np.inf)))
        rj = e.reveal_joint if getattr(e, "reveal_joint", None) is not None else j
        sel, selv = np.flatnonzero(ser["joint"] == j), np.flatnonzero(ser["jointv"] == j)
        x, xv = _signal(ser["sig"], e.reveal, sel, rj), _signal(ser["sigv"], e.reveal, selv, rj)
        if x is None or xv is None:
            notes.append(f"effect {i} ({e.kind}): signal {e.reveal!r} not in the plot data")
            continue
        lab = _signal_label(e.reveal)
        xlabel = lab if e.reveal == "t" else f"{lab} of joint {rj + 1}"
        B.append(residual_figure(
            f"diagnosis-effect-{i}-{_slug(e.kind)}",
            f"Effect {i}: {e.kind} on {_effect_who(e)}: residual of joint {j + 1} before and after, "
            f"against the {lab} that revealed it",
            [("identification data", x, rb[sel], ra[sel]), ("validation data", xv, rvb[selv], rva[selv])],
            xlabel, max_points=max_points, n_bins=n_bins, dpi=dpi))
    rid, rv = ser["rounds"][-1]
    tag = "final model (declared + effects)" if diag.effects else "declared model"
    B.append(torque_figure("diagnosis-torque-identification", f"Identification data: measured and reconstructed "
                           f"torque, {tag}", ser["Y"], ser["Y"] - rid, ser["joint"], n,
                           rel_err=diag.after_rel_err, max_points=max_points, dpi=dpi))
    B.append(torque_figure("diagnosis-torque-validation", f"Validation data: measured and reconstructed torque, {tag}",
                           ser["Yv"], ser["Yv"] - rv, ser["jointv"], n, rel_err=diag.after_validation_rel_err,
                           max_points=max_points, dpi=dpi))
    return B


def diagnosis_html(diagnosis) -> str:
    """HTML tables of a :class:`~symoro_gen.diagnostics.ResidualReport` (errors before/after, effects
    added, best candidates per round, structure left, warnings), without plots: for ``_repr_html_``."""
    blocks = _diagnosis_blocks(diagnosis, False, MAX_POINTS, N_BINS, DPI, [])
    blocks += warnings_block(getattr(diagnosis, "warnings", ()))
    return '<div class="symoro-gen-diagnosis">' + render_html_fragment(blocks) + "</div>"


# ---- the report ------------------------------------------------------------------------------------
def build_report(result=None, *, title: str | None = None, robot: str | None = None,
                 sources: Mapping[str, Sequence[str]] | None = None, identification=None, validation=None,
                 payload_names: Sequence[str] | None = None, payload=None, drive=None, reference=None,
                 diagnosis=None, text: str | None = None, notes: Sequence[str] = (), plots: bool = True,
                 max_points: int = MAX_POINTS, n_bins: int = N_BINS, dpi: int = DPI,
                 raw_errors: Sequence[tuple[str, Sequence[float]]] = ()) -> Report:
    """A report of an identification (and/or a residual diagnosis): the papers' tables and plots.

    Parameters
    ----------
    result : IdentificationResult, optional
        Default with ``diagnosis``: its final (augmented) model ``diagnosis.result_after``.
    title : str, optional
    robot : str, optional
        Robot name, for the default title.
    sources : mapping label -> list of str, optional
        Data files, e.g. ``{"identification": [...], "validation": [...]}``.
    identification, validation : ObservationSystem, or sequence of them or of (label, system), or mapping
        Systems the torques are reconstructed on (measured vs reconstructed per joint, Fig. 3 of the
        LWR4 paper) and whose relative error norms are tabulated (Table III); the identification
        systems also give the singular values of W.
    payload_names : sequence of str, optional
        The payload's parameters (default: the columns not common to every identification system).
    payload : IdentificationResult, optional
        Payload re-identified with the robot known (Table IV).
    drive : DriveGainsResult, optional
        Per-joint drive gains (RX-90 Table 4), with cond(W) per joint.
    reference : sequence of ReferenceRow, optional
        :func:`~symoro_gen.identification.reference.compare_with_reference` rows.
    diagnosis : ResidualReport, optional
        Errors before/after, effects, candidates, residual vs revealing signal plots.
    text : str, optional
        Text summary shown verbatim at the end (e.g. ``result.summary()``).
    notes : sequence of str
        Extra remarks listed under "Notes".
    plots : bool
        False: tables only (no matplotlib needed).
    max_points : int
        Most samples drawn per curve.
    n_bins : int
        Bins of the binned-mean curves of residual plots.
    dpi : int
        Figure resolution (figures are ``11 * dpi`` pixels wide).
    raw_errors : sequence of (label, errors per joint)
        Raw-torque relative error norms (the model at full rate on the filtered states against the
        unfiltered measured torque, ``rel_err_raw``) listed below the filtered ones; the result's own
        ``rel_err_raw`` (identification data) is listed first when it has one.

    Returns
    -------
    Report

    Raises
    ------
    MissingDependencyError
        ``plots`` and matplotlib is not installed.
    """
    if plots:
        require_matplotlib()
    if result is None and diagnosis is not None:
        result = diagnosis.result_after
    ident = _labelled(identification, "identification data")
    valid = _labelled(validation, "validation data")
    notes = list(notes)
    if title is None:
        what = "Residual diagnosis" if diagnosis is not None and not ident else "Identification"
        name = robot or getattr(diagnosis, "robot", None)
        title = f"{what} of {name}" if name else what
    B: list = []
    intro = []
    if result is not None:
        intro.append(("Final model (declared + effects): " if diagnosis is not None and result is diagnosis.result_after
                      else "") + result_overview(result) + ".")
    for label, files in (sources or {}).items():
        if files:
            intro.append(f"{label[:1].upper() + label[1:]}: {', '.join(map(str, files))}.")
    if intro:
        B.append(Paragraph(" ".join(intro)))

    if result is not None and (ident or valid or diagnosis is None):
        n = result.n_joints
        basis = basis_text(getattr(result, "rel_err_basis", None))
        rows = [("identification (as fitted)", result.rel_err)]
        if len(ident) > 1:
            rows += [(lab, result.rel_err_on(s)) for lab, s in ident if _can_predict(result, s)]
        rows += [(lab, result.rel_err_on(s)) for lab, s in valid if _can_predict(result, s)]
        raw = list(raw_errors)
        if getattr(result, "rel_err_raw", None) is not None:
            raw.insert(0, ("identification data", result.rel_err_raw))
        B.append(Heading("Quality of the torque reconstruction"))
        B.append(rel_err_table(rows, n, caption=f"Relative error norms ‖ρ_j‖/‖Y_j‖ per joint on the {basis}"))
        if raw:
            B.append(raw_err_table(raw, n))
        gains = getattr(result, "gains", None)
        if drive is not None or gains is not None:
            B.append(Heading("Gains"))
            if drive is not None:
                B.append(drive_gains_table(drive))
            elif gains is not None:
                B.append(gains_table(gains, "Torque-sensor gains (IDIM-TLS, LWR4 eq. 8-16)"
                                     if str(result.method).upper().startswith("TLS") else "Gains"))
        pnames = _payload_names(result, ident, payload_names)
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

    if diagnosis is not None:
        B += _diagnosis_blocks(diagnosis, plots, max_points, n_bins, dpi, notes)

    if plots and result is not None and (ident or valid):
        B.append(Heading("Measured and reconstructed torques"))
        for group in (ident, valid):
            for lab, s in group:
                if not _can_predict(result, s):
                    notes.append(f"{lab}: columns {[c for c in s.names if c not in result.parameter_map()]} are "
                                 f"not parameters of the result: torques not reconstructed")
                    continue
                y = result.scaled_measurements(s)
                B.append(torque_figure(f"torque-{_slug(lab)}",
                                       f"{lab[:1].upper() + lab[1:]}: measured"
                                       f"{' (× identified gain)' if getattr(result, 'gains', None) is not None else ''}"
                                       f" and reconstructed torque per joint",
                                       y, result.predict(s), s.joint, result.n_joints,
                                       rel_err=result.rel_err_on(s), max_points=max_points, dpi=dpi))
    if plots and result is not None and ident:
        est = [nm for nm in result.names if any(nm in s.names for _, s in ident)]
        if est:
            sv = scaled_singular_values([sy for _, sy in ident], est)
            cond = sv[0] / sv[-1] if sv[-1] > 0 else math.inf
            B.append(Heading("Conditioning of the observation matrix"))
            B.append(singular_values_figure(
                "singular-values", sv,
                title=f"Singular values of W, columns scaled to unit norm: cond = {fmt_value(cond)}",
                caption=f"Singular values of the identification observation matrix W restricted to the {len(est)} "
                        f"estimated parameters, each column scaled to unit norm, rows unweighted: condition number "
                        f"{fmt_value(cond)}. As solved (rows weighted by the method{', gain columns included' if getattr(result, 'gains', None) is not None else ''}): "
                        f"cond(W) = {fmt_value(result.cond)}, with unit-norm columns {fmt_value(result.cond_scaled)}.",
                dpi=dpi))

    if result is not None:
        B.append(Heading("Parameters of the final model" if diagnosis is not None else "Identified parameters"))
        B.append(parameter_table(result, "Parameters: value, 2σ, %σ (= 100 σ/|value|); rows shaded: %σ > 30"))
        if getattr(result, "joint_sigma", None) is not None:
            B.append(Paragraph("Row weights 1/σ_j with σ_j = " + ", ".join(fmt_value(x) for x in result.joint_sigma)))
    if reference:
        B.append(Heading("Reference"))
        B.append(reference_table(reference))
    warns = unique_in_order(list(getattr(result, "warnings", ()) if result is not None else ())
                    + list(getattr(drive, "warnings", ()) if drive is not None else ())
                    + list(getattr(payload, "warnings", ()) if payload is not None else ())
                    + list(getattr(diagnosis, "warnings", ()) if diagnosis is not None else ()))
    if warns:
        B += warnings_block(warns)
    if notes:
        B += [Heading("Notes", 3), ItemList(tuple(notes))]
    if text:
        B += [Heading("Text summary", 3), Preformatted(text)]
    return Report(title, tuple(B), footer=f"symoro_gen {__version__}")


def check_report_path(path) -> str:
    """``"html"`` or ``"md"`` for a report path; :class:`ReportError` for another suffix (check it before
    a long computation)."""
    kind = report_kind(path)
    if kind is None:
        raise ReportError(f"report {path}: unknown suffix {Path(path).suffix!r}; use one of "
                          f"{', '.join(REPORT_SUFFIXES)}")
    return kind


def write_report(path, result=None, *, force: bool = False, **kwargs) -> Path:
    """Build a report (:func:`build_report`, same keyword arguments) and write it to ``path``:
    ``.html``/``.htm`` one self-contained page (images as base64 PNG, no external asset),
    ``.md``/``.markdown`` Markdown with its images in ``<stem>_files/`` beside it. Atomic (temporary
    file + rename); an existing file symoro-gen did not write is replaced only with ``force``
    (:func:`~symoro_gen.report.document.write_report_files`).

    Returns
    -------
    Path
    """
    path = Path(path)
    check_report_path(path)
    return write_report_files(build_report(result, **kwargs), path, force=force)
