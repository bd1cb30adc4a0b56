"""The residual diagnosis' own report blocks and HTML (Jupyter), drawn with the generic toolkit of
:mod:`symoro_gen.report`: errors before and after, the effects added, the best candidates of every round, the
structure left, and the residual of each effect's joint before and after against the signal that revealed it.
:class:`~symoro_gen.diagnostics.report.ResidualReport` is read through its public attributes only.
"""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..report.document import Heading, Paragraph, Table
from ..report.plots import DPI, MAX_POINTS, N_BINS, error_bars_figure, residual_figure, torque_figure
from ..report.tables import fmt_pct, fmt_value, html_fragment, raw_err_table, rel_err_table, slug, warnings_block
from .structure import SIGNAL_LABELS

__all__ = ["N_CANDIDATES", "diagnosis_blocks", "diagnosis_html", "diagnosis_plot_series"]

#: best candidates listed per round of a diagnosis
N_CANDIDATES = 10


def diagnosis_plot_series(diagnosis) -> dict | None:
    """The arrays behind a diagnosis' residual plots, from its public objects.

    Reads ``diagnosis.plot_data`` (``frame`` and ``vframe`` with ``system`` and ``sig``,
    ``round_resid``: ``[(identification residual, validation residual)]``, before the first effect then
    after each); returns None when they are not there.

    Returns
    -------
    dict or None
        ``Y``, ``joint``, ``sig`` (identification), ``Yv``, ``jointv``, ``sigv`` (validation),
        ``rounds`` (list of (r_id, r_val)), ``effect_rounds`` (the round each loop effect kept was named in, in
        the order of ``rounds[1:]``; None when the diagnosis does not say).
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
               "rounds": [(np.asarray(a, float), np.asarray(b, float)) for a, b in rr],
               "effect_rounds": pd.get("effect_rounds")}
    except (AttributeError, TypeError, ValueError):
        return None
    if not out["rounds"] or any(a.shape != out["Y"].shape or b.shape != out["Yv"].shape for a, b in out["rounds"]):
        return None
    return out


def _fmt_given(x) -> str:
    """A value that may not apply (None or NaN: a friction law has no validation z; null in the JSON): '-'."""
    return fmt_value(x if x is not None and np.isfinite(x) else None)


def residual_position(effect, ser: Mapping) -> int | None:
    """Where the residual after ``effect`` is in ``ser["rounds"]`` (its residual before it the one before), or
    None when it has none there (a friction law or a note: not an effect of the loop's rounds). ``rounds[k]`` is
    the residual after the first ``k`` loop effects kept, which is not round ``k`` once the stability stage has
    dropped an effect or a friction law has won a round."""
    k = int(getattr(effect, "round", 0) or 0)
    order = ser.get("effect_rounds")
    if order is not None:
        k = list(order).index(k) + 1 if k in order and effect.kind != "friction_law" else 0
    return k if 1 <= k < len(ser["rounds"]) else None


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


def diagnosis_blocks(diag, notes: list, *, plots: bool = True, max_points: int = MAX_POINTS, n_bins: int = N_BINS,
                     dpi: int = DPI) -> list:
    """The report blocks of a diagnosis (``notes`` receives what could not be drawn)."""
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
            pl = getattr(e, "plausibility", None)
            rows.append((str(i), e.kind, _effect_who(e), params, phys, fmt_value(e.score), f"{e.p_value:.2e}",
                         _fmt_given(e.z_validation), getattr(e, "verdict", "") or "-",
                         "-" if pl is None else f"{float(pl.score):.2f}"))
        B.append(Table(("#", "Effect", "Where", "Parameters (value, %σ)", "Physical reading", "Score", "p",
                        "z_val", "Verdict", "Plausibility"), tuple(rows), "Effects added, in order",
                       numeric=(True, False, False, False, False, True, True, True, False, True),
                       row_classes=tuple("added" if getattr(e, "verdict", "cause") in ("cause", "") else ""
                                         for e in diag.effects)))
        # the verdict of each effect in words: a doubtful or rejected effect is never called the cause
        for i, e in enumerate(diag.effects, 1):
            lines = e.verdict_lines() if hasattr(e, "verdict_lines") else []
            if lines:
                B.append(Paragraph(f"Effect {i} ({e.kind} on {_effect_who(e)}): " + " — ".join(lines)))
    else:
        B.append(Paragraph("No effect added: no candidate was significant on the identification data and better "
                           "than noise on the held-out acceptance data (the end of each identification experiment)."))
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
        k = residual_position(e, ser)
        if k is None:
            notes.append(f"effect {i} ({e.kind}): no residual figure (a friction law changes the model's own "
                         "friction columns, chosen by cross-validation: its errors are in the effects table)"
                         if e.kind == "friction_law" else
                         f"effect {i} ({e.kind}): no residual of round {getattr(e, 'round', i)} in the plot data")
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
            f"diagnosis-effect-{i}-{slug(e.kind)}",
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
    blocks = diagnosis_blocks(diagnosis, [], plots=False)
    blocks += warnings_block(getattr(diagnosis, "warnings", ()))
    return html_fragment(blocks, "symoro-gen-diagnosis")
