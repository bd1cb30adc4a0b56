"""Reports of identifications and residual diagnoses: the papers' tables and matplotlib plots, as one
self-contained HTML page or as Markdown with its images beside it; HTML tables for Jupyter.

Typical use::

    from symoro_gen.report import write_report
    write_report("lwr4.html", result, robot="lwr4", identification={"identification data": sys_u},
                 validation={"validation data": sys_v})          # or "lwr4.md"
    write_report("diag.html", diagnosis=residual_report)         # symoro_gen.diagnostics.diagnose(...)

Plots need matplotlib (the ``plots`` extra); without it :func:`write_report` raises
:class:`MissingDependencyError` naming the extra, and ``plots=False`` writes the tables alone.
"""
from .build import (
                    build_report,
                    check_report_path,
                    diagnosis_html,
                    diagnosis_plot_series,
                    scaled_singular_values,
                    write_report,
)
from .document import (
                    REPORT_SUFFIXES,
                    Figure,
                    Heading,
                    ItemList,
                    Paragraph,
                    Preformatted,
                    Report,
                    ReportError,
                    Table,
                    asset_folder,
                    png_size,
                    report_kind,
)
from .plots import MissingDependencyError, require_matplotlib
from .tables import drive_gains_html, gains_html, result_html

__all__ = ["build_report", "write_report", "check_report_path", "diagnosis_plot_series", "scaled_singular_values",
           "Report", "Heading", "Paragraph", "Table", "Figure", "ItemList", "Preformatted", "ReportError",
           "REPORT_SUFFIXES", "asset_folder", "png_size", "report_kind", "MissingDependencyError",
           "require_matplotlib", "result_html", "gains_html", "drive_gains_html", "diagnosis_html"]
