"""The fleet report: flags, skipped logs, the fleet estimate, and for every flagged parameter its values
over the days for the flagged robot against the other robots and the fleet band (reuses
:mod:`symoro_gen.report`: one self-contained HTML page or Markdown with its images)."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..report.document import (
    Figure,
    Heading,
    Paragraph,
    Preformatted,
    Report,
    Table,
    write_report_files,
)
from ..report.plots import figure_and_axes, figure_png, require_matplotlib

if TYPE_CHECKING:  # the engine's result holds report() and figures(), which call this module
    from .engine import FleetResult

__all__ = ["flag_figures", "fleet_report", "write_fleet_report"]


def _flag_figure(res: FleetResult, flag: dict, idx: int, dpi: int = 90) -> Figure:
    """One parameter over the days: every robot (grey), the flagged one (red, ±2σ), the fleet band."""
    k = res.names.index(flag["parameter"])
    fig, axes = figure_and_axes(1, 1, ax_h=2.6, gap=0.3, top=0.4, bottom=0.6, dpi=dpi)
    ax = axes[0, 0]
    all_days = sorted({d for r in res.days for d in res.days[r]})
    x_of = {d: i for i, d in enumerate(all_days)}
    for r in res.days:
        days, v, s = res.series(r, flag["parameter"])
        x = [x_of[d] for d in days]
        if r == flag["robot"]:
            ax.errorbar(x, v, yerr=2 * s, color="#c62828", marker="o", lw=1.8, capsize=3, label=f"{r} (flagged)",
                        zorder=3)
        else:
            ax.plot(x, v, color="#9e9e9e", lw=0.8, marker=".", zorder=1)
    tau = res.level["tau_all"][k]
    m = flag["fleet_reference"]
    if np.isfinite(tau):
        ax.axhspan(m - 2 * tau, m + 2 * tau, color="#1565c0", alpha=0.12, label="fleet ± 2 between-robot std")
    ax.axhline(m, color="#1565c0", lw=1.0, label="fleet (other robots)")
    ax.set_xticks(range(len(all_days)))
    ax.set_xticklabels(all_days, rotation=30, fontsize=8)
    ax.set_ylabel(flag["parameter"])
    ax.set_title(f"{flag['robot']} {flag['parameter']}: {flag['test']} z = {flag['z']:.1f}", fontsize=10)
    ax.legend(fontsize=7, loc="best")
    safe = "".join(c if c.isalnum() else "-" for c in f"flag-{idx}-{flag['robot']}-{flag['parameter']}")
    return Figure(safe, figure_png(fig, dpi), caption=f"{flag['parameter']} of {flag['robot']} over the days (error "
                  "bars ±2σ of each day's estimate) among the other robots (grey) and the fleet band", figure=fig)


def flag_figures(res: FleetResult) -> list[Figure]:
    """The figure of every flagged parameter (its matplotlib figure kept in ``Figure.figure``)."""
    return [_flag_figure(res, f, i) for i, f in enumerate(res.flagged)]


def fleet_report(res: FleetResult, *, plots: bool = True) -> Report:
    """The :class:`~symoro_gen.report.Report` of a fleet run (``plots``: with the flagged parameters' figures,
    which need the 'plots' extra: without matplotlib :class:`~symoro_gen.report.MissingDependencyError` names it,
    whether or not a robot is flagged, as every report of the library).

    Raises
    ------
    MissingDependencyError
        ``plots`` and matplotlib is not installed.
    """
    if plots:
        require_matplotlib()
    blocks: list = [Paragraph(res.summary().splitlines()[0])]
    blocks.append(Heading("Flags"))
    if not res.flagged:
        blocks.append(Paragraph("No robot drifts away from the fleet (level and trend tests, "
                                f"{res.settings.get('correction', 'holm')}-corrected at alpha = "
                                f"{res.settings.get('alpha')})."))
    else:
        rows = tuple((f["robot"], f["parameter"], f["test"], f"{f['z']:.2f}", f"{f['p_adjusted']:.2g}",
                      ", ".join(f["days"])) for f in res.flagged)
        blocks.append(Table(("robot", "parameter", "test", "z", "p (adjusted)", "days"), rows,
                            caption="Flagged robots and parameters", numeric=(False, False, False, True, True, False)))
        if plots:
            blocks += flag_figures(res)
    if res.diagnoses:
        blocks.append(Heading("Closed loop: diagnosis of the flagged robots"))
        for r, d in res.diagnoses.items():
            what = f"{r}, day {d['day']} ({', '.join(d['files'])}; flagged on {', '.join(d['parameters'])})"
            if "error" in d:
                blocks.append(Paragraph(f"{what}: not run ({d['error']})."))
            else:
                blocks += [Paragraph(what + ":"), Preformatted(str(d["summary"]))]
    if res.skipped:
        blocks.append(Heading("Skipped logs"))
        blocks.append(Table(("file", "reason"), tuple((s["file"], s["error"]) for s in res.skipped),
                            numeric=(False, False)))
    blocks.append(Heading("Fleet estimate"))
    tau = res.level["tau_all"]
    blocks.append(Table(("parameter", "value", "std", "between-robot std"),
                        tuple((n, f"{v:.6g}", f"{s:.3g}", f"{t:.3g}") for n, v, s, t in
                              zip(res.names, res.fleet.values, res.fleet.std, tau)),
                        caption="Pooled IDIM-WLS of every log; between-robot std by DerSimonian-Laird"))
    return Report(title=f"Fleet of {len(res.robots)} {res.model} robots", blocks=tuple(blocks))


def write_fleet_report(path, res: FleetResult, *, plots: bool = True, force: bool = False) -> Path:
    """Write the fleet report as ``.html`` (self-contained) or ``.md`` (an existing file symoro-gen did
    not write is replaced only with ``force``)."""
    return write_report_files(fleet_report(res, plots=plots), path, force=force)
