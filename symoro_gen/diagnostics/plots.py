"""PNG plots of a residual diagnosis, written to a folder (``symoro-gen diagnose --plots DIR``).

The figures are those of the diagnosis section of the report (:mod:`symoro_gen.diagnostics.render`) (matplotlib, Agg backend):
relative error norms per joint before/after, and for every effect added the residual of its joint
before and after it, against the signal that revealed it (identification and validation data), plus
measured vs reconstructed torques of the final model.
"""
from __future__ import annotations

from pathlib import Path

from ..atomic import check_replaceable, mark_png, write_bytes_atomic, written_by_symoro
from ..report import Figure, MissingDependencyError, require_matplotlib
from .render import diagnosis_blocks

__all__ = ["existing_plots", "write_figures", "write_plots"]

#: every figure of a diagnosis is named ``diagnosis-*.png``; older ones in the folder are replaced
STEM = "diagnosis-"


def existing_plots(folder) -> list[Path]:
    """The ``diagnosis-*.png`` files already in ``folder``: :func:`write_plots` replaces or removes them."""
    folder = Path(folder)
    return sorted(folder.glob(f"{STEM}*.png")) if folder.is_dir() else []


def write_plots(report, folder, *, force: bool = False) -> list[Path]:
    """Write the diagnosis figures of ``report`` (a :class:`~.report.ResidualReport`) as PNG files.

    Returns
    -------
    list of Path
        Files written, ``folder/<figure name>.png``; empty when matplotlib is not installed. Files
        ``diagnosis-*.png`` of an earlier diagnosis in the folder that this one does not write are removed.

    Raises
    ------
    OutputError
        Without ``force``, a ``diagnosis-*.png`` in the folder that symoro-gen did not write (nothing written).
    """
    try:
        require_matplotlib()
    except MissingDependencyError:
        return []
    figures = [b for b in diagnosis_blocks(report, [], plots=True) if isinstance(b, Figure)]
    return write_figures(figures, folder, force=force)


def write_figures(figures: list[Figure], folder, *, force: bool = False) -> list[Path]:
    """Write ``figures`` (named ``diagnosis-*``) as ``folder/<name>.png``, after the rule of :func:`write_plots`:
    an existing ``diagnosis-*.png`` symoro-gen did not write stops everything without ``force``, and those of an
    earlier diagnosis that these figures do not replace are removed."""
    folder = Path(folder)
    for old in existing_plots(folder):  # replaced or removed below: only symoro-gen's, unless force
        check_replaceable(old, force, label="plot")
    folder.mkdir(parents=True, exist_ok=True)
    names = {f"{fig.name}.png" for fig in figures}
    for old in existing_plots(folder):   # figures of an earlier diagnosis in the same folder
        if old.name not in names and (force or written_by_symoro(old)):
            old.unlink()
    out = []
    for fig in figures:
        p = folder / f"{fig.name}.png"
        write_bytes_atomic(p, mark_png(fig.png))
        out.append(p)
    return out
