"""PNG plots of a residual diagnosis, written to a folder (``symoro-gen diagnose --plots DIR``).

The figures are those of the diagnosis section of :mod:`symoro_gen.report` (matplotlib, Agg backend):
relative error norms per joint before/after, and for every effect added the residual of its joint
before and after it, against the signal that revealed it (identification and validation data), plus
measured vs reconstructed torques of the final model.
"""
from __future__ import annotations

from pathlib import Path

from ..atomic import write_bytes_atomic
from ..report import MissingDependencyError, build_report

__all__ = ["write_plots"]

#: every figure of a diagnosis is named ``diagnosis-*.png``; older ones in the folder are replaced
STEM = "diagnosis-"


def write_plots(report, folder) -> list[Path]:
    """Write the diagnosis figures of ``report`` (a :class:`~.report.ResidualReport`) as PNG files.

    Returns
    -------
    list of Path
        Files written, ``folder/<figure name>.png``; empty when matplotlib is not installed. Files
        ``diagnosis-*.png`` of an earlier diagnosis in the folder that this one does not write are removed.
    """
    try:
        rep = build_report(diagnosis=report, robot=report.robot, plots=True)
    except MissingDependencyError:
        return []
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    names = {f"{fig.name}.png" for fig in rep.figures}
    for old in folder.glob(f"{STEM}*.png"):   # figures of an earlier diagnosis in the same folder
        if old.name not in names:
            old.unlink()
    out = []
    for fig in rep.figures:
        p = folder / f"{fig.name}.png"
        write_bytes_atomic(p, fig.png)
        out.append(p)
    return out
