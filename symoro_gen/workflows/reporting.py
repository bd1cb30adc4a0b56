"""A report of an identification and/or a residual diagnosis, composed of the blocks each stage renders for
itself (:mod:`symoro_gen.identification.render`, :mod:`symoro_gen.diagnostics.render`) with the generic
toolkit of :mod:`symoro_gen.report`; written as one self-contained HTML page or as Markdown with its images
beside it. Inputs are read, never modified.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from .. import __version__
from ..diagnostics.render import diagnosis_blocks
from ..identification.render import IdentificationBlocks, identification_blocks, result_overview
from ..report.document import Heading, ItemList, Paragraph, Preformatted, Report, check_report_path, write_report_files
from ..report.plots import DPI, MAX_POINTS, N_BINS, require_matplotlib
from ..report.tables import unique_in_order, warnings_block

__all__ = ["ReportContent", "build_report", "write_report"]


@dataclass(frozen=True, eq=False)
class ReportContent:
    """Everything a report shows besides the result and the diagnosis.

    Attributes
    ----------
    title : str, optional
        Default: "Identification of ROBOT" or "Residual diagnosis of ROBOT".
    robot : str, optional
    sources : mapping label -> list of str
        Data files, e.g. ``{"identification data": [...], "validation data": [...]}``.
    blocks : IdentificationBlocks
        Systems, payload, drive gains, reference and raw errors of the identification.
    text : str, optional
        Text summary shown verbatim at the end (e.g. ``result.summary()``).
    notes : sequence of str
        Extra remarks listed under "Notes".
    plots : bool
        False: tables only (no matplotlib needed).
    max_points, n_bins, dpi : int
        Most samples drawn per curve, bins of the residual plots' binned means, figure resolution.
    """

    title: str | None = None
    robot: str | None = None
    sources: Mapping[str, Sequence[str]] = field(default_factory=dict)
    blocks: IdentificationBlocks = field(default_factory=IdentificationBlocks)
    text: str | None = None
    notes: Sequence[str] = ()
    plots: bool = True
    max_points: int = MAX_POINTS
    n_bins: int = N_BINS
    dpi: int = DPI


def _title(content: ReportContent, diagnosis, has_systems: bool) -> str:
    if content.title is not None:
        return content.title
    what = "Residual diagnosis" if diagnosis is not None and not has_systems else "Identification"
    name = content.robot or getattr(diagnosis, "robot", None)
    return f"{what} of {name}" if name else what


def build_report(result=None, diagnosis=None, content: ReportContent | None = None) -> Report:
    """A report of an identification (``result``) and/or a residual diagnosis (``diagnosis``; its final model
    ``diagnosis.result_after`` is the result by default): the papers' tables and plots.

    Raises
    ------
    MissingDependencyError
        ``content.plots`` and matplotlib is not installed.
    """
    c = content or ReportContent()
    if c.plots:
        require_matplotlib()
    if result is None and diagnosis is not None:
        result = diagnosis.result_after
    ident = None
    if result is not None:
        ident = identification_blocks(result, c.blocks, diagnosed=diagnosis is not None, plots=c.plots,
                                      max_points=c.max_points, dpi=c.dpi)
    has_systems = c.blocks.identification is not None
    intro = []
    if result is not None:
        final = diagnosis is not None and result is diagnosis.result_after
        intro.append(("Final model (declared + effects): " if final else "") + result_overview(result) + ".")
    for label, files in (c.sources or {}).items():
        if files:
            intro.append(f"{label[:1].upper() + label[1:]}: {', '.join(map(str, files))}.")
    B: list = [Paragraph(" ".join(intro))] if intro else []
    notes = list(c.notes)
    if ident is not None:
        B += ident.quality
    if diagnosis is not None:
        B += diagnosis_blocks(diagnosis, notes, plots=c.plots, max_points=c.max_points, n_bins=c.n_bins, dpi=c.dpi)
    if ident is not None:
        B += ident.figures + ident.parameters
        notes += ident.notes
    warns = unique_in_order(list(getattr(result, "warnings", ()) if result is not None else ())
                            + list(ident.warnings if ident is not None else ())
                            + list(getattr(diagnosis, "warnings", ()) if diagnosis is not None else ()))
    B += warnings_block(warns)
    if notes:
        B += [Heading("Notes", 3), ItemList(tuple(notes))]
    if c.text:
        B += [Heading("Text summary", 3), Preformatted(c.text)]
    return Report(_title(c, diagnosis, has_systems), tuple(B), footer=f"symoro_gen {__version__}")


def write_report(path, result=None, diagnosis=None, content: ReportContent | None = None, *,
                 force: bool = False) -> Path:
    """:func:`build_report` written to ``path``: ``.html``/``.htm`` one self-contained page (images as base64
    PNG), ``.md``/``.markdown`` Markdown with its images in ``<stem>_files/`` beside it. Atomic; an existing
    file symoro-gen did not write is replaced only with ``force``."""
    path = Path(path)
    check_report_path(path)
    return write_report_files(build_report(result, diagnosis, content), path, force=force)
