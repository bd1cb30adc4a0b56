"""The papers' tables as report blocks, from result objects (no plotting, no matplotlib).

Used by :func:`symoro_gen.report.build_report` and by the ``_repr_html_`` methods of the result
objects (Jupyter). Result objects are read through their public attributes only.
"""
from __future__ import annotations

import math
import re
from collections.abc import Sequence

import numpy as np

from .document import Heading, ItemList, Paragraph, Table, render_html_fragment

__all__ = ["fmt_value", "fmt_pct", "parameter_table", "gains_table", "drive_gains_table", "rel_err_table",
           "payload_table", "reference_table", "warnings_block", "result_blocks", "result_html", "gains_html",
           "drive_gains_html", "POOR_PCT", "is_mass_name", "unique_in_order"]

#: %sigma above which a parameter row is marked as poorly identified (the estimators' warning level)
POOR_PCT = 30.0

_MASS = re.compile(r"^M\d+$")


def is_mass_name(name: str) -> bool:
    """``M8`` is a mass; ``MX8`` is a first moment."""
    return bool(_MASS.match(str(name)))


def fmt_value(x) -> str:
    """4 significant digits; scientific notation outside [1e-3, 1e5); ``inf``/``nan`` spelled out."""
    if x is None:
        return "-"
    x = float(x)
    if not math.isfinite(x):
        return "nan" if math.isnan(x) else ("inf" if x > 0 else "-inf")
    if x == 0:
        return "0"
    return f"{x:.4g}" if 1e-3 <= abs(x) < 1e5 else f"{x:.3e}"


def fmt_known(x) -> str:
    """A known (given) value with up to 6 significant digits, as the user wrote it."""
    x = float(x)
    return f"{x:.6g}" if math.isfinite(x) else fmt_value(x)


def fmt_pct(x) -> str:
    """A %sigma with 2 decimals (``inf`` for parameters that are 0 or not identifiable)."""
    if x is None:
        return "-"
    x = float(x)
    if not math.isfinite(x):
        return "nan" if math.isnan(x) else "inf"
    return f"{x:.2f}"


def fmt_err(x) -> str:
    """A relative error norm with 4 decimals."""
    x = float(x)
    return f"{x:.4f}" if math.isfinite(x) else "-"


def _poor(pct: float) -> bool:
    return not (float(pct) <= POOR_PCT)


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
            rows.append((n, fmt_value(v), fmt_value(2 * s), fmt_pct(p), "poorly identified" if _poor(p) else ""))
            classes.append("poor" if _poor(p) else "")
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
        classes.append("poor" if _poor(p) else "")
    return Table(tuple(head), tuple(rows), caption, numeric=(False,) + (True,) * (len(head) - 1),
                 row_classes=tuple(classes))


def drive_gains_table(dg, caption: str = "Drive gains, per-joint weighted LS with a known payload (RX-90 eq. 27)") -> Table:
    return gains_table(dg.gains, caption, cond=[r.cond for r in dg.per_joint])


def rel_err_table(rows: Sequence[tuple[str, Sequence[float]]], n_joints: int,
                  caption: str = "Relative error norms ‖ρ_j‖/‖Y_j‖ per joint") -> Table:
    """One row per data set, one column per joint (LWR4 paper Table III)."""
    head = ("Data",) + tuple(f"joint {j + 1}" for j in range(n_joints))
    body = []
    for label, errs in rows:
        e = list(np.asarray(errs, float).reshape(-1))
        e += [math.nan] * (n_joints - len(e))
        body.append((label,) + tuple(fmt_err(x) for x in e[:n_joints]))
    return Table(head, tuple(body), caption)


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


def warnings_block(warnings: Sequence[str]) -> list:
    """Numbered warnings (as ``summary()`` numbers them)."""
    if not warnings:
        return []
    return [Heading("Warnings", 3), ItemList(tuple(str(w) for w in warnings), ordered=True)]


def unique_in_order(items) -> tuple[str, ...]:
    out: list[str] = []
    for w in items:
        if w not in out:
            out.append(w)
    return tuple(out)


def result_overview(result) -> str:
    from ..identification.result import method_label

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


def _fragment(blocks) -> str:
    return '<div class="symoro-gen-result">' + render_html_fragment(blocks) + "</div>"


def result_html(result) -> str:
    """HTML tables of an :class:`~symoro_gen.identification.result.IdentificationResult` (Jupyter)."""
    return _fragment(result_blocks(result))


def gains_html(gains) -> str:
    """HTML table of a :class:`~symoro_gen.identification.result.Gains` (Jupyter)."""
    return _fragment([gains_table(gains)])


def drive_gains_html(dg) -> str:
    """HTML of a :class:`~symoro_gen.identification.gains.DriveGainsResult` (Jupyter)."""
    return _fragment([drive_gains_table(dg)] + warnings_block(dg.warnings))
