"""The reports' generic toolkit: documents (headings, paragraphs, tables, figures, preformatted text) rendered as
one self-contained HTML page or as Markdown with its images beside it; matplotlib figures of torques, residuals,
singular values and error bars; number formats and per-joint error tables. It imports no domain object: each
stage renders its own blocks with it (:mod:`symoro_gen.identification.render`,
:mod:`symoro_gen.diagnostics.render`), and the workflows compose them (:mod:`symoro_gen.workflows.reporting`:
``write_report``; ``symoro_gen.identify(...).report(path)``).

Plots need matplotlib (the ``plots`` extra); without it the figures raise :class:`MissingDependencyError` naming
the extra.
"""
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
                    check_report_path,
                    png_size,
                    render_html_fragment,
                    report_kind,
                    write_report_files,
)
from .plots import MissingDependencyError, require_matplotlib

__all__ = ["check_report_path", "Report", "Heading", "Paragraph", "Table", "Figure", "ItemList", "Preformatted",
           "ReportError", "MissingDependencyError", "require_matplotlib", "REPORT_SUFFIXES", "asset_folder", "png_size",
           "render_html_fragment", "report_kind", "write_report_files"]
