"""The reports and figures of a floating-base robot's ``identify`` and ``diagnose`` results, composed with the generic
toolkit of :mod:`symoro_gen.report` (as :mod:`symoro_gen.workflows.export_report` does for an export).

* ``identify``: each identified row's measured right-hand side ``Y`` (the joint torques and the contact wrenches
  carried to the rows by the frames' Jacobians, [AVN2014]) against the model ``W chi`` on the validation logs (or
  on the identification logs without them), the relative error norm per row position ([LWR4-TLS] Table III; the
  filtered, decimated rows and the raw full-rate ones, [GB-gains] eq. 15-16), the identified combinations ``K chi``
  with their 2 sigma bars ([GB-gains] eq. 17-21).
* ``diagnose``: the validation error per row before and after the loop with the effects it named on each row, or,
  for logs without joint torques, the contact-sensor checks' p-values against their Bonferroni level.

The numbers are the result's own (``to_dict()``); nothing is recomputed here but the model's rows ``W chi`` the
figures draw.
"""
from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import __version__
from ..report.document import (
    Figure,
    Heading,
    ItemList,
    Paragraph,
    Preformatted,
    Report,
    Table,
    check_report_path,
    write_report_files,
)
from ..report.plots import DPI, MAX_POINTS, figure_and_axes, figure_png, require_matplotlib, torque_figure
from ..report.tables import fmt_err, fmt_pct, fmt_value, is_poor, warnings_block

if TYPE_CHECKING:  # the results objects hold report() and figures(), which call this module
    from .floating import FloatingDiagnoseResults, FloatingIdentifyResults

__all__ = ["rows_figure", "row_errors_figure", "parameters_figure", "identify_figures", "identify_report",
           "loop_errors_figure", "checks_figure", "diagnose_figures", "P_FLOOR", "diagnose_report", "write_floating_report"]

#: the smallest p-value drawn (``-log10 p`` at most 300): an F test's p underflows to 0 for a gross effect
P_FLOOR = 1e-300
#: the bar colours of the error series: light the identification logs, dark the validation ones
SERIES_COLORS = ("#bdbdbd", "#64b5f6", "#616161", "#0d47a1")

#: the row kinds of ``--kind`` in words
_KIND_WORDS = {"base": "base-wrench", "joints": "joint", "both": "base-wrench and joint"}


def rows_figure(name: str, title: str, Y: np.ndarray, Yhat: np.ndarray, row_names: Sequence[str],
                rel_err: Sequence[float], *, max_points: int = MAX_POINTS, dpi: int = DPI) -> Figure:
    """Measured rows ``Y`` and the model's ``W chi`` (both ``(m, k)``: samples by row positions), one subplot per
    row position, against the decimated sample (:func:`symoro_gen.report.plots.torque_figure`, its panels named by
    row); each subplot titled with its row's relative error norm ``rel_err``."""
    Y, Yhat = np.asarray(Y, float), np.asarray(Yhat, float)
    k = len(row_names)
    stride = max(1, math.ceil(Y.shape[0] / max(int(max_points), 1)))
    cap = (f"{title}. Blue: the measured row (joint torques and contact wrenches carried by the frames' Jacobians); "
           "red dashed: the model with the identified combinations; x axis: decimated samples, logs one after the "
           "other" + (f" (one sample in {stride} drawn)" if stride > 1 else "") + ".")
    return torque_figure(name, title, Y.ravel(), Yhat.ravel(), np.tile(np.arange(k), Y.shape[0]), k,
                         rel_err=list(rel_err), ylabel="N or N·m", caption=cap, max_points=max_points, dpi=dpi,
                         panels=row_names)


def _bars(ax, labels: Sequence[str], series: Sequence[tuple[str, Sequence[float]]]) -> None:
    """Grouped bars, one group per label, one bar per series (NaN drawn as 0)."""
    width = 0.8 / max(len(series), 1)
    for k, (name, values) in enumerate(series):
        v = np.asarray(values, float).reshape(-1)
        ax.bar(np.arange(v.size) + (k - (len(series) - 1) / 2) * width, np.nan_to_num(v), width, label=name,
               color=SERIES_COLORS[k % len(SERIES_COLORS)])
    ax.set_xticks(np.arange(len(labels)), list(labels), fontsize=8)
    ax.tick_params(labelsize=8)
    ax.grid(True, axis="y", color="#e0e0e0", lw=0.6)


def row_errors_figure(name: str, title: str, row_names: Sequence[str],
                      series: Sequence[tuple[str, Sequence[float]]], *, dpi: int = DPI) -> Figure:
    """Relative error norms ``‖ρ‖/‖Y‖`` per row position, one bar per series (e.g. identification and validation)."""
    fig, axes = figure_and_axes(1, 1, ax_h=2.2, gap=0.0, top=0.35, bottom=0.45, dpi=dpi, right=2.6)
    ax = axes[0][0]
    _bars(ax, row_names, series)
    ax.set_ylabel("‖ρ‖/‖Y‖", fontsize=9)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.0, 1.0), frameon=False)
    ax.set_title(title, fontsize=10, loc="left")
    return Figure(name, figure_png(fig, dpi), title, figure=fig)


def parameters_figure(name: str, title: str, names: Sequence[str], values: np.ndarray, std: np.ndarray, *,
                      dpi: int = DPI) -> Figure:
    """Each identified combination with its ``± 2 sigma`` bar (symmetric-log scale: the masses and the small
    first moments on one axis)."""
    fig, axes = figure_and_axes(1, 1, ax_h=2.6, gap=0.0, top=0.35, bottom=0.8, dpi=dpi)
    ax = axes[0][0]
    x = np.arange(len(names))
    v, s = np.asarray(values, float), np.asarray(std, float)
    ax.errorbar(x, v, yerr=2 * np.nan_to_num(s), fmt="o", ms=3.5, color="#1565c0", ecolor="#e65100", elinewidth=1.2,
                capsize=2, label="value ± 2σ")
    finite = np.abs(v[np.isfinite(v) & (v != 0)])
    ax.set_yscale("symlog", linthresh=float(1e-3 * finite.max()) if finite.size else 1.0)
    ax.axhline(0.0, color="#000000", lw=0.6)
    ax.set_xticks(x, list(names), rotation=90, fontsize=6 if len(names) > 40 else 8)
    ax.tick_params(axis="y", labelsize=8)
    ax.grid(True, axis="y", color="#e0e0e0", lw=0.6)
    ax.set_title(title, fontsize=10, loc="left")
    return Figure(name, figure_png(fig, dpi), f"{title}: each value with a bar of twice its standard deviation",
                  figure=fig)


def _error_series(res: FloatingIdentifyResults) -> list[tuple[str, Sequence[float]]]:
    series: list[tuple[str, Sequence[float]]] = [("identification, filtered", res.rel_err[0]),
                                                 ("identification, raw", res.rel_err[1])]
    if res.validation is not None:
        series += [("validation, filtered", res.validation["rel_err"]),
                   ("validation, raw", res.validation["rel_err_raw"])]
    return series


def identify_figures(res: FloatingIdentifyResults, *, dpi: int = DPI) -> list[Figure]:
    """The figures of a floating-base identification (module docstring)."""
    require_matplotlib()
    on_validation = res.validation is not None
    Y, Yhat = res.row_predictions(validation=on_validation)
    share = "validation logs" if on_validation else "identification logs"
    err = res.validation["rel_err"] if res.validation is not None else res.rel_err[0]
    r = res.fit.result
    return [rows_figure("floating-rows", f"{res.robot.name}: the {_KIND_WORDS.get(res.kind, res.kind)} rows, measured and modelled ({share})",
                        Y, Yhat, res.row_names, err, dpi=dpi),
            row_errors_figure("floating-row-errors", f"{res.robot.name}: relative error norm per row", res.row_names,
                              _error_series(res), dpi=dpi),
            parameters_figure("floating-parameters", f"{res.robot.name}: the {len(r.names)} identified combinations "
                              "K chi", r.names, r.values, r.std, dpi=dpi)]


def _parameters_table(res: FloatingIdentifyResults) -> Table:
    r = res.fit.result
    pct = np.asarray(r.rel_std_pct, float)
    return Table(("combination", "value", "σ", "2σ", "%σ"),
                 tuple((n, fmt_value(v), fmt_value(s), fmt_value(2 * s), fmt_pct(p))
                       for n, v, s, p in zip(r.names, r.values, r.std, pct)),
                 caption=f"Identified combinations K chi ({r.method.upper()}; relations in the JSON's "
                         "floating.relations; orange: %σ above 30)",
                 row_classes=tuple("poor" if is_poor(p) else "" for p in pct))


def _errors_table(row_names: Sequence[str], series: Sequence[tuple[str, Sequence[float]]], caption: str) -> Table:
    return Table(("row", *(s for s, _ in series)),
                 tuple((name, *(fmt_err(v[i]) if v[i] is not None else "-" for _, v in series))
                       for i, name in enumerate(row_names)), caption=caption)


def identify_report(res: FloatingIdentifyResults, *, plots: bool = True) -> Report:
    """The report of a floating-base identification: what was identified from what, the errors per row, the
    combinations with their standard deviations, the figures, the not identifiable parameters, the text."""
    r = res.fit.result
    files = res.files()
    intro = (f"The {_KIND_WORDS.get(res.kind, res.kind)} rows ({' '.join(res.row_names)}) of {res.robot.name} identified by "
             f"{r.method.upper()} ({res.weighting} weighting): {len(r.names)} identifiable combinations of the "
             f"{len(res.model.STANDARD_NAMES)} standard parameters, from {len(files)} log(s)"
             + (f", validated on {', '.join(map(str, res.validation['data']))}" if res.validation else "") + ".")
    blocks: list = [Paragraph(intro), Heading("Errors per row"),
                    _errors_table(res.row_names, _error_series(res), "Relative error norm ‖ρ‖/‖Y‖ per row position "
                                  "(filtered: the decimated system; raw: the model at full rate against the raw rows)")]
    if plots:
        blocks += identify_figures(res)
    blocks += [Heading("Identified combinations"), _parameters_table(res)]
    if res.fit.not_identifiable:
        blocks += [Paragraph("Not identifiable from these rows: " + " ".join(res.fit.not_identifiable))]
    blocks += [Heading("Data"), Table(("log", "samples", "rows", "contacts", "torques", "base rates", "cut-off [Hz]",
                                       "n_d"),
                                      tuple((f["file"], f["rows_read"], f["rows"], ", ".join(f["contacts"]) or "none",
                                             "yes" if f["torques"] else "no", f["orientation"],
                                             f"{f['cutoff_hz']:.4g}", f["n_d"]) for f in files))]
    blocks += warnings_block(list(r.warnings))
    blocks += [Heading("Text summary", 3), Preformatted(res.summary())]
    return Report(f"Floating-base identification of {res.robot.name}", tuple(blocks),
                  footer=f"symoro_gen {__version__}")


# ---- diagnose ----------------------------------------------------------------------------------------------------
def _effect_where(d: Mapping[str, Any]) -> str:
    return str(d.get("row") or f"sensor {d.get('frame')}")


def loop_errors_figure(name: str, title: str, loop: Mapping[str, Any], *, dpi: int = DPI) -> Figure:
    """The loop's validation error per row before and after, each effect's label (and verdict) written above its
    row (a contact sensor's effect, on every row its wrench reaches, in the upper left corner)."""
    fig, axes = figure_and_axes(1, 1, ax_h=2.4, gap=0.0, top=0.35, bottom=0.45, dpi=dpi, right=2.6)
    ax = axes[0][0]
    rows = list(loop["rows"])
    before = [np.nan if v is None else v for v in loop["rel_err_before"]]
    after = [np.nan if v is None else v for v in loop["rel_err_after"]]
    _bars(ax, rows, [("validation, before", before), ("validation, after", after)])
    top = np.nanmax(np.r_[before, after, 0.0])
    per_row: dict[str, list[str]] = {}
    sensors = []
    for d in loop["effects"]:
        label = d["label"] + (f" ({d['verdict']})" if d.get("verdict") else "")
        if d.get("row"):
            per_row.setdefault(d["row"], []).append(label)
        else:
            sensors.append(label)
    for row, labels in per_row.items():
        i = rows.index(row)
        ax.text(i, 1.02 * top, "\n".join(labels), ha="center", va="bottom", fontsize=7, rotation=0)
    if sensors:
        ax.text(0.01, 0.98, "sensors: " + ", ".join(sensors), transform=ax.transAxes, ha="left", va="top", fontsize=7)
    ax.set_ylim(0, 1.35 * top if top > 0 else 1.0)
    ax.set_ylabel("‖ρ‖/‖Y‖", fontsize=9)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.0, 1.0), frameon=False)
    ax.set_title(title, fontsize=10, loc="left")
    return Figure(name, figure_png(fig, dpi), f"{title}: the last share of each log, held out from the final fit; "
                  "above a row, the effects the loop named on it", figure=fig)


def checks_figure(name: str, title: str, checks: Sequence[Mapping[str, Any]], level: float, *,
                  dpi: int = DPI) -> Figure:
    """The contact-sensor checks: ``-log10 p`` of each identifiable candidate (as last tested; accepted ones dark)
    against the Bonferroni level (a p below :data:`P_FLOOR`, 0 in double precision, drawn at the floor)."""
    fig, axes = figure_and_axes(1, 1, ax_h=2.2, gap=0.0, top=0.35, bottom=0.9, dpi=dpi)
    ax = axes[0][0]
    shown = [c for c in checks if c["identifiable"]]
    heights = [-math.log10(max(c["p_value"], P_FLOOR)) for c in shown]
    ax.bar(np.arange(len(shown)), heights, 0.6, color=["#0d47a1" if c["accepted"] else "#bdbdbd" for c in shown])
    ax.axhline(-math.log10(level), color="#e65100", lw=1.2, ls="--", label=f"level {level:.3g}")
    ax.set_xticks(np.arange(len(shown)), [f"{c['frame']} {c['effect']}" for c in shown], rotation=30, fontsize=8)
    ax.set_ylabel("-log10 p", fontsize=9)
    ax.tick_params(axis="y", labelsize=8)
    ax.grid(True, axis="y", color="#e0e0e0", lw=0.6)
    ax.legend(fontsize=8, loc="upper right", frameon=False)
    ax.set_title(title, fontsize=10, loc="left")
    return Figure(name, figure_png(fig, dpi), f"{title}: dark, accepted; the dashed line the Bonferroni level",
                  figure=fig)


def diagnose_figures(res: FloatingDiagnoseResults, *, dpi: int = DPI) -> list[Figure]:
    """The figures of a floating-base diagnosis (module docstring), named ``diagnosis-*`` (``--plots DIR``)."""
    require_matplotlib()
    out = []
    if res.loop is not None:
        out.append(loop_errors_figure("diagnosis-floating-rows", f"{res.robot.name}: validation error per row, "
                                      "before and after the loop", res.loop, dpi=dpi))
    if res.checks:
        out.append(checks_figure("diagnosis-floating-checks", f"{res.robot.name}: contact-sensor checks on the "
                                 f"{res.checks[0]['kind']} rows", res.checks, res.level, dpi=dpi))
    return out


def _effects_table(loop: Mapping[str, Any]) -> Table:
    rows = []
    for d in loop["effects"]:
        vals = "; ".join(f"{n} {fmt_value(v)} ± {fmt_value(d['std'].get(n))}" for n, v in d["params"].items()
                         if v is not None)
        rows.append((_effect_where(d), d["label"], d["round"], d["verdict"] or "-", vals))
    return Table(("row", "effect", "round", "verdict", "parameters ± σ"), tuple(rows),
                 caption="Effects the loop named (a contact sensor's on every row its wrench reaches)",
                 numeric=(False, False, True, False, False))


def _checks_table(checks: Sequence[Mapping[str, Any]]) -> Table:
    rows = []
    for c in checks:
        if not c["identifiable"]:
            rows.append((c["kind"], c["frame"], c["effect"], "not identifiable", "-", c["reason"]))
            continue
        vals = "; ".join(f"{n} {fmt_value(v)} ± {fmt_value(s)}" for n, v, s in zip(c["components"], c["estimate"],
                                                                                    c["std"]))
        rows.append((c["kind"], c["frame"], c["effect"], f"accepted ({c['round']})" if c["accepted"] else "not accepted",
                     f"{c['p_value']:.3g}", vals))
    return Table(("rows", "frame", "effect", "verdict", "p", "estimate ± σ"), tuple(rows),
                 caption="Contact-sensor checks (nested F tests in forward selection)",
                 numeric=(False, False, False, False, True, False))


def diagnose_report(res: FloatingDiagnoseResults, *, plots: bool = True) -> Report:
    """The report of a floating-base diagnosis: the loop's effects with their verdicts, the unexplained check and
    the errors per row before and after (or the contact-sensor checks), the figures, the text."""
    data = [str(r.signals.recording.source) for r in res.rows]
    blocks: list = [Paragraph(f"Diagnosis of {res.robot.name} (floating base) on {', '.join(data)}.")]
    loop = res.loop
    if loop is not None:
        blocks += [Heading("Effects"), _effects_table(loop) if loop["effects"] else
                   Paragraph("No effect beyond the noise on any row.")]
        reasons = [f"{d['label']}: {d['verdict']}, {d['verdict_reason']}" for d in loop["effects"]
                   if d.get("verdict_reason")]
        if reasons:
            blocks += [ItemList(tuple(reasons))]
        flagged = [u for u in loop["unexplained"] if u["flagged"]]
        blocks += [Heading("Unexplained structure"),
                   Table(("row", "out-of-fold R²", "threshold", "flagged", "signals"),
                         tuple((u["row"], fmt_value(u["share"]), fmt_value(u["threshold"]),
                                "yes" if u["flagged"] else "no", ", ".join(u["signals"][:4])) for u in
                               loop["unexplained"]),
                         caption=f"{len(flagged)} row(s) flagged", numeric=(False, True, True, False, False))]
        blocks += [Heading("Errors per row"),
                   _errors_table(loop["rows"], [("validation, before", loop["rel_err_before"]),
                                                ("validation, after", loop["rel_err_after"])],
                                 "Relative error norm per row on the validation share, before and after the loop")]
    else:
        blocks += [Paragraph(f"The loop did not run: {res.loop_note}")]
    if res.checks:
        blocks += [Heading("Contact-sensor checks"), _checks_table(res.checks)]
    if plots:
        blocks += diagnose_figures(res)
    blocks += warnings_block(list(loop["warnings"]) if loop is not None else [])
    blocks += [Heading("Text summary", 3), Preformatted(res.summary())]
    return Report(f"Residual diagnosis of {res.robot.name} (floating base)", tuple(blocks),
                  footer=f"symoro_gen {__version__}")


def write_floating_report(path: str | os.PathLike[str], res: Any, *, force: bool = False) -> Path:
    """Write the report of ``res`` (a floating-base identify or diagnose result) as ``.html`` (self-contained) or
    ``.md`` (images beside it), after the outputs rule (:meth:`~symoro_gen.workflows.base.Results.check_output`)."""
    check_report_path(path)
    require_matplotlib()
    res.check_output(path, force=force, label="report", report=True)
    report = identify_report(res) if res.command == "identify" else diagnose_report(res)
    return write_report_files(report, path, force=force)

