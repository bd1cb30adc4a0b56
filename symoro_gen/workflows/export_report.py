"""The report and figure of an export (``export_urdf``, ``export_mjcf``, ``export_par``): every body's mass, centre
of mass and rotational inertia as the exported file holds them beside the robot file's nominal values, the drive
terms and the exporter's notes, composed with the generic toolkit of :mod:`symoro_gen.report`.

The body values are the rigid-body quantities of the standard parameters ``XX .. M`` of each link, [KD2002]
ch. 9 (inverse parallel-axis theorem, :func:`~symoro_gen.description.inertia.com_from_standard`); for a URDF or
MJCF export, those the file holds after the exporter made a body physically consistent
(:func:`~symoro_gen.description.urdf_export.inertial_of`, which the exporters call).
"""
from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .. import __version__
from ..description.inertia import com_from_standard
from ..description.model import RobotDescription
from ..description.urdf_export import inertial_of, link_values
from ..params import INERTIAL_KINDS, param_name
from ..report.document import Figure, Heading, ItemList, Paragraph, Preformatted, Report, Table, write_report_files
from ..report.plots import figure_and_axes, figure_png, require_matplotlib

if TYPE_CHECKING:  # the results object holds report() and figures(), which call this module
    from .export import ExportResults

__all__ = ["BodyValues", "body_values", "bodies_figure", "export_report", "write_export_report"]

#: the exports whose file holds each body made physically consistent (``inertial_of``); ``.par`` holds the values
PHYSICAL_EXPORTS = ("export-urdf", "export-mjcf")


@dataclass(frozen=True, eq=False)
class BodyValues:
    """One body, nominal and exported: ``mass`` [kg], ``com`` [m] (in the link's frame), ``inertia`` the rotational
    inertia at the centre of mass [kg m²] (3 x 3)."""

    frame: int
    label: str
    nominal_mass: float
    mass: float
    nominal_com: np.ndarray
    com: np.ndarray
    nominal_inertia: np.ndarray
    inertia: np.ndarray

    @property
    def com_shift(self) -> float:
        """How far the centre of mass moved from nominal [m]."""
        return float(np.linalg.norm(self.com - self.nominal_com))

    @property
    def inertia_change_rel(self) -> float | None:
        """``‖I_c − I_c,nom‖_F / ‖I_c,nom‖_F`` (None without a nominal inertia)."""
        ref = float(np.linalg.norm(self.nominal_inertia))
        return float(np.linalg.norm(self.inertia - self.nominal_inertia)) / ref if ref > 0 else None


def _frames(robot: RobotDescription) -> list[tuple[int, str]]:
    out = [(0, "base link")] if robot.floating else []
    out += [(r.j, f"link {r.j}") for r in robot.joints]
    if robot.payload is not None:
        out.append((robot.payload, f"payload (frame {robot.payload})"))
    return out


def _rigid(vals: Mapping[str, float], j: int, physical: bool) -> tuple[float, np.ndarray, np.ndarray] | None:
    p10 = [float(vals.get(param_name(k, j), 0.0)) for k in INERTIAL_KINDS]
    if not any(p10):
        return None
    if physical:
        m, c, ic = inertial_of(dict(vals), j, [], "export")  # what the file holds; the notes already say it
        return float(m), np.asarray(c, float), np.asarray(ic, float)
    m, c, ic = com_from_standard(p10)
    return float(m), np.asarray(c, float), np.asarray(ic, float)


def body_values(robot: RobotDescription, values: Mapping[str, float], command: str) -> list[BodyValues]:
    """Every body with inertial parameters, nominal (the robot file's ``[nominal]``, zero when absent) and as
    exported (``values``: every standard and payload parameter written)."""
    physical = command in PHYSICAL_EXPORTS
    nominal = link_values(robot)
    zero3, zero33 = np.zeros(3), np.zeros((3, 3))
    out = []
    for j, label in _frames(robot):
        nom, exp = _rigid(nominal, j, physical), _rigid(values, j, physical)
        if nom is None and exp is None:
            continue
        nm, nc, ni = nom if nom is not None else (0.0, zero3, zero33)
        m, c, ic = exp if exp is not None else (0.0, zero3, zero33)
        out.append(BodyValues(j, label, nm, m, nc, c, ni, ic))
    return out


def bodies_figure(res: ExportResults, dpi: int = 90) -> Figure:
    """Mass, centre-of-mass shift and trace of the inertia at the centre of mass of every body, nominal against
    exported (one bar pair per body)."""
    require_matplotlib()
    bodies = body_values(res.robot, res.values or {}, res.command)
    fig, axes = figure_and_axes(1, 3, ax_h=2.6, gap=0.3, top=0.45, bottom=0.9, dpi=dpi)
    x = np.arange(len(bodies))
    labels = [b.label.replace("payload ", "payload\n") for b in bodies]
    w = 0.38
    panels = (("mass [kg]", [b.nominal_mass for b in bodies], [b.mass for b in bodies]),
              ("tr I_c [kg m²]", [float(np.trace(b.nominal_inertia)) for b in bodies],
               [float(np.trace(b.inertia)) for b in bodies]))
    for ax, (title, nom, exp) in zip((axes[0, 0], axes[0, 2]), panels):
        ax.bar(x - w / 2, nom, w, color="#9e9e9e", label="nominal (robot file)")
        ax.bar(x + w / 2, exp, w, color="#1565c0", label="exported")
        ax.set_title(title, fontsize=10)
    ax = axes[0, 1]
    ax.bar(x, [1e3 * b.com_shift for b in bodies], 0.6, color="#e65100")
    ax.set_title("centre of mass moved from nominal [mm]" if res.robot.nominal is not None else
                 "centre of mass from the frame origin [mm] (no nominal)", fontsize=10)
    for ax in axes[0]:
        ax.set_xticks(x)
        ax.set_xticklabels(labels, rotation=30, fontsize=8)
    axes[0, 0].legend(fontsize=7, loc="best")
    made = " (each made physically consistent as the file holds it)" if res.command in PHYSICAL_EXPORTS else ""
    return Figure(f"{res.command}-bodies", figure_png(fig, dpi),
                  caption=f"{res.robot.name}: every body's mass, centre-of-mass shift and inertia at the centre of "
                          f"mass as exported{made}, beside the robot file's nominal values", figure=fig)


def _bodies_table(bodies: list[BodyValues]) -> Table:
    rows = []
    for b in bodies:
        rel = b.inertia_change_rel
        rows.append((b.label, f"{b.nominal_mass:.6g}", f"{b.mass:.6g}", f"{1e3 * b.com_shift:.3g}",
                     "n/a" if rel is None else f"{100 * rel:.3g}"))
    return Table(("body", "nominal mass [kg]", "exported mass [kg]", "CoM shift [mm]", "inertia change [%]"),
                 tuple(rows), caption="Bodies as exported against the robot file's nominal values (inertia change: "
                                      "relative Frobenius norm of the change of the inertia at the centre of mass)")


def export_report(res: ExportResults) -> Report:
    """The :class:`~symoro_gen.report.Report` of an export: what was exported from what, the bodies (table and
    figure), the drive terms (with an identification), the exporter's notes and the exported text."""
    what = {"export-urdf": "URDF", "export-mjcf": "MuJoCo MJCF", "export-par": "SYMORO+ .par"}.get(res.command,
                                                                                                   res.command)
    src = (res.sidecar or {}).get("from")
    blocks: list = [Paragraph(f"{what} of {res.robot.name} from {res.robot.file or 'its description'}"
                              + (f", every body from the identification {src}" if src else "")
                              + (f" (regrouping {'exact' if res.sidecar and res.sidecar.get('exact') else 'closest'}"
                                 f", base error {res.sidecar.get('base_error'):.3g})"
                                 if res.sidecar and res.sidecar.get("base_error") is not None else "") + ".")]
    bodies = body_values(res.robot, res.values or {}, res.command)
    blocks += [Heading("Bodies"), _bodies_table(bodies), bodies_figure(res)]
    drive = (res.sidecar or {}).get("drive") or {}
    if drive:
        kinds = sorted({k for d in drive.values() for k in d})
        blocks += [Heading("Drive terms"),
                   Table(("joint", *kinds), tuple((j, *(f"{d[k]:.6g}" if k in d else "" for k in kinds))
                                                  for j, d in drive.items()),
                         caption=str((res.sidecar or {}).get("drive_note", "")))]
    if res.notes:
        blocks += [Heading("Notes"), ItemList(tuple(res.notes))]
    blocks += [Heading("Exported text"), Preformatted(res.text)]
    return Report(f"{what} export of {res.robot.name}", tuple(blocks), footer=f"symoro_gen {__version__}")


def write_export_report(path: str | os.PathLike[str], res: ExportResults, *, force: bool = False) -> Path:
    """Write the export's report as ``.html`` (self-contained) or ``.md`` (images beside it)."""
    return write_report_files(export_report(res), path, force=force)
