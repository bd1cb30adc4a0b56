"""A report as a list of small immutable blocks, rendered to one self-contained HTML page (images
embedded as base64 PNG, no external asset, no script) or to Markdown (images written beside it).

Blocks: :class:`Heading`, :class:`Paragraph`, :class:`Table`, :class:`Figure`, :class:`ItemList`,
:class:`Preformatted`. Text is plain text: the renderers escape it (HTML entities; ``|`` in Markdown
tables). Writing is atomic: a temporary sibling renamed over the target (:func:`write_report_files`).
"""
from __future__ import annotations

import base64
import html
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..atomic import (
    GENERATOR,
    MARKDOWN_MARK,
    Target,
    check_replaceable,
    mark_png,
    replace_folder_atomic,
    write_bytes_atomic,
)
from ..errors import SymoroError

__all__ = ["ReportError", "Heading", "Paragraph", "Table", "Figure", "ItemList", "Preformatted", "Report", "png_size",
           "render_html_fragment", "report_kind", "asset_folder", "report_targets", "write_report_files", "REPORT_SUFFIXES",
           "check_report_path"]

#: suffixes :func:`write_report_files` accepts, and the format each means
REPORT_SUFFIXES = {".html": "html", ".htm": "html", ".md": "md", ".markdown": "md"}

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


class ReportError(SymoroError, ValueError):
    """A report cannot be written as asked (unknown suffix, image folder in the way...)."""


def png_size(png: bytes) -> tuple[int, int]:
    """``(width, height)`` in pixels from a PNG's IHDR chunk.

    Raises
    ------
    ValueError
        Not a PNG.
    """
    if len(png) < 24 or png[:8] != _PNG_SIGNATURE or png[12:16] != b"IHDR":
        raise ValueError("not a PNG image (bad signature or no IHDR chunk)")
    w, h = struct.unpack(">II", png[16:24])
    return int(w), int(h)


@dataclass(frozen=True)
class Heading:
    text: str
    level: int = 2


@dataclass(frozen=True)
class Paragraph:
    text: str


@dataclass(frozen=True)
class Preformatted:
    text: str


@dataclass(frozen=True)
class ItemList:
    items: tuple[str, ...]
    ordered: bool = False


@dataclass(frozen=True)
class Table:
    """A table of text cells.

    Attributes
    ----------
    header : tuple of str
    rows : tuple of tuple of str
        Each as long as ``header``.
    caption : str
    numeric : tuple of bool
        Right-aligned columns (default: every column but the first).
    row_classes : tuple of str
        Per-row CSS class in HTML (``""`` for none; e.g. ``"poor"`` for a poorly identified parameter).
    """

    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    caption: str = ""
    numeric: tuple[bool, ...] = ()
    row_classes: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "header", tuple(str(h) for h in self.header))
        object.__setattr__(self, "rows", tuple(tuple(str(c) for c in r) for r in self.rows))
        n = len(self.header)
        for k, r in enumerate(self.rows):
            if len(r) != n:
                raise ValueError(f"Table {self.caption!r}: row {k} has {len(r)} cells for {n} columns")
        if not self.numeric:
            object.__setattr__(self, "numeric", tuple(i > 0 for i in range(n)))
        if len(self.numeric) != n:
            raise ValueError(f"Table {self.caption!r}: numeric has {len(self.numeric)} entries for {n} columns")
        if not self.row_classes:
            object.__setattr__(self, "row_classes", ("",) * len(self.rows))
        if len(self.row_classes) != len(self.rows):
            raise ValueError(f"Table {self.caption!r}: row_classes has {len(self.row_classes)} entries "
                             f"for {len(self.rows)} rows")


@dataclass(frozen=True, eq=False)
class Figure:
    """A PNG image.

    Attributes
    ----------
    name : str
        File stem in the Markdown asset folder (letters, digits, ``-`` and ``_``).
    png : bytes
    caption : str
    width, height : int
        Pixels, read from the PNG.
    figure : matplotlib.figure.Figure or None
        The figure drawn (kept for ``plot()``), not part of the document.
    """

    name: str
    png: bytes
    caption: str = ""
    width: int = field(init=False)
    height: int = field(init=False)
    #: the matplotlib figure the PNG was drawn from, when kept (``.plot()`` of a result returns it)
    figure: Any = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if not self.name or not all(c.isalnum() or c in "-_" for c in self.name):
            raise ValueError(f"Figure name {self.name!r}: use letters, digits, '-' and '_' only")
        w, h = png_size(self.png)
        object.__setattr__(self, "width", w)
        object.__setattr__(self, "height", h)


_CSS = """
body { margin: 0; background: #ffffff; color: #1a1a1a;
       font: 14px/1.45 "DejaVu Sans", "Liberation Sans", Helvetica, Arial, sans-serif; }
main { padding: 16px 24px 40px 24px; }
h1 { font-size: 22px; margin: 0 0 8px 0; }
h2 { font-size: 18px; margin: 26px 0 8px 0; border-bottom: 1px solid #d0d0d0; padding-bottom: 2px; }
h3 { font-size: 15px; margin: 18px 0 6px 0; }
p { margin: 6px 0; max-width: 1100px; }
div.table { margin: 6px 0 12px 0; }
p.caption { font-weight: bold; margin: 2px 0 4px 0; }
table { border-collapse: collapse; font-size: 13px; }
th, td { border: 1px solid #c8c8c8; padding: 2px 8px; }
th { background: #eef1f5; }
td.num, th.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
tr.poor td { background: #fff3e0; }
tr.added td { background: #e8f5e9; }
figure { margin: 10px 0 18px 0; }
figure img { display: block; max-width: none; border: 0; }
figcaption { font-size: 13px; color: #444444; margin-top: 4px; max-width: 1100px; }
pre { background: #f6f8fa; padding: 8px; font-size: 12px; overflow-x: auto; max-width: 1100px; }
ol, ul { margin: 4px 0; max-width: 1100px; }
footer { margin-top: 30px; font-size: 12px; color: #666666; }
"""


def _e(text: str) -> str:
    return html.escape(str(text), quote=True)


def _html_block(b, parts: list[str]) -> None:
    if isinstance(b, Heading):
        lv = min(max(int(b.level), 1), 6)
        parts.append(f"<h{lv}>{_e(b.text)}</h{lv}>")
    elif isinstance(b, Paragraph):
        parts.append(f"<p>{_e(b.text)}</p>")
    elif isinstance(b, Preformatted):
        parts.append(f"<pre>{_e(b.text)}</pre>")
    elif isinstance(b, ItemList):
        tag = "ol" if b.ordered else "ul"
        parts.append(f"<{tag}>" + "".join(f"<li>{_e(i)}</li>" for i in b.items) + f"</{tag}>")
    elif isinstance(b, Table):
        cls = ["num" if n else "" for n in b.numeric]
        head = "".join(f'<th class="{c}">{_e(h)}</th>' if c else f"<th>{_e(h)}</th>" for h, c in zip(b.header, cls))
        rows = []
        for r, rc in zip(b.rows, b.row_classes):
            cells = "".join(f'<td class="{c}">{_e(x)}</td>' if c else f"<td>{_e(x)}</td>" for x, c in zip(r, cls))
            rows.append(f'<tr class="{_e(rc)}">{cells}</tr>' if rc else f"<tr>{cells}</tr>")
        cap = f'<p class="caption">{_e(b.caption)}</p>' if b.caption else ""
        parts.append(f'<div class="table">{cap}<table><thead><tr>{head}</tr></thead><tbody>{"".join(rows)}'
                     f"</tbody></table></div>")
    elif isinstance(b, Figure):
        data = base64.b64encode(b.png).decode("ascii")
        parts.append(f'<figure id="fig-{_e(b.name)}"><img src="data:image/png;base64,{data}" '
                     f'width="{b.width}" height="{b.height}" alt="{_e(b.caption or b.name)}">'
                     + (f"<figcaption>{_e(b.caption)}</figcaption>" if b.caption else "") + "</figure>")
    else:
        raise TypeError(f"unknown report block {type(b).__name__}")


def render_html_fragment(blocks) -> str:
    """HTML of some blocks without the page around them (for Jupyter's ``_repr_html_``)."""
    parts: list[str] = []
    for b in blocks:
        _html_block(b, parts)
    return "\n".join(parts)


def _md_cell(x: str) -> str:
    return str(x).replace("\\", "\\\\").replace("|", "\\|").replace("\n", " ")


def _md_block(b, parts: list[str], folder: str) -> None:
    if isinstance(b, Heading):
        parts.append("#" * min(max(int(b.level), 1), 6) + " " + b.text)
    elif isinstance(b, Paragraph):
        parts.append(b.text)
    elif isinstance(b, Preformatted):
        parts.append("```\n" + b.text.rstrip("\n") + "\n```")
    elif isinstance(b, ItemList):
        parts.append("\n".join((f"{i}. " if b.ordered else "- ") + it.replace("\n", " ")
                               for i, it in enumerate(b.items, 1)))
    elif isinstance(b, Table):
        lines = []
        if b.caption:
            lines += [f"**{b.caption}**", ""]
        lines.append("| " + " | ".join(_md_cell(h) for h in b.header) + " |")
        lines.append("|" + "|".join("---:" if n else "---" for n in b.numeric) + "|")
        lines += ["| " + " | ".join(_md_cell(c) for c in r) + " |" for r in b.rows]
        parts.append("\n".join(lines))
    elif isinstance(b, Figure):
        alt = (b.caption or b.name).replace("[", "(").replace("]", ")").replace("\n", " ")
        parts.append(f"![{alt}]({folder}/{b.name}.png)" + (f"\n\n*{b.caption}*" if b.caption else ""))
    else:
        raise TypeError(f"unknown report block {type(b).__name__}")


@dataclass(frozen=True, eq=False)
class Report:
    """A report: title and blocks. Render with :meth:`to_html` or :meth:`to_markdown`."""

    title: str
    blocks: tuple = ()
    footer: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "blocks", tuple(self.blocks))
        names = [b.name for b in self.figures]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"Report: duplicate figure names {dup}")

    @property
    def figures(self) -> tuple[Figure, ...]:
        return tuple(b for b in self.blocks if isinstance(b, Figure))

    def to_html(self) -> str:
        """One self-contained page: inline CSS, images as ``data:`` URIs, no script, no external URL."""
        body = render_html_fragment((Heading(self.title, 1),) + self.blocks)
        foot = f"<footer>{_e(self.footer)}</footer>" if self.footer else ""
        return ("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
                f"<meta name=\"generator\" content=\"{GENERATOR}\">\n<title>{_e(self.title)}</title>\n<style>{_CSS}</style>\n</head>\n<body>\n<main>\n"
                f"{body}\n{foot}\n</main>\n</body>\n</html>\n")

    def to_markdown(self, folder: str) -> str:
        """Markdown text; figures are linked as ``folder/<name>.png`` (write them there)."""
        parts = [f"# {self.title}"]
        for b in self.blocks:
            _md_block(b, parts, folder)
        if self.footer:
            parts.append(f"<sub>{self.footer}</sub>")
        return "\n\n".join(parts) + "\n"


def report_kind(path) -> str | None:
    """``"html"``, ``"md"`` or None (unknown suffix) for a report path."""
    return REPORT_SUFFIXES.get(Path(path).suffix.lower())


def asset_folder(path) -> Path:
    """Folder of a Markdown report's images: ``<stem>_files`` beside it."""
    path = Path(path)
    return path.with_name(path.stem + "_files")


def report_targets(option: str, path) -> dict[str, Target]:
    """The files a report at ``path`` writes, for :func:`symoro_gen.atomic.check_outputs`: the report and,
    for Markdown, its image folder (replaced whole)."""
    out = {option: Target(Path(path))}
    if report_kind(path) == "md":
        out[f"{option} (its image folder)"] = Target(asset_folder(path), folder=True)
    return out


def _replace_folder_atomic(folder: Path, files: dict[str, bytes]) -> None:
    """Write ``files`` into a temporary sibling folder, then swap it in place of ``folder``."""
    if folder.exists() and not folder.is_dir():
        raise ReportError(f"{folder} exists and is not a folder: cannot write the report's images there")
    replace_folder_atomic(folder, files)


def write_report_files(report: Report, path, *, force: bool = False) -> Path:
    """Write ``report`` to ``path`` (``.html``/``.htm``: one self-contained page; ``.md``/``.markdown``:
    the text, with its images in ``<stem>_files/`` beside it), atomically.

    An existing report (and image folder) is replaced only when symoro-gen wrote it (its mark: a
    ``generator`` meta tag, a last Markdown comment line, PNG images with a ``Software`` chunk), unless
    ``force`` (:func:`symoro_gen.atomic.check_replaceable`).

    Returns
    -------
    Path
        The report file.

    Raises
    ------
    ReportError
        Unknown suffix.
    OutputError
        An existing file or image folder that symoro-gen did not write, without ``force``.
    """
    path = Path(path)
    kind = report_kind(path)
    if kind is None:
        raise ReportError(f"report {path}: unknown suffix {path.suffix!r}; use one of {', '.join(REPORT_SUFFIXES)}")
    check_replaceable(path, force, label="report")
    if kind == "md" and report.figures:
        check_replaceable(asset_folder(path), force, folder=True, label="report image folder")
    path.parent.mkdir(parents=True, exist_ok=True)
    if kind == "html":
        write_bytes_atomic(path, report.to_html().encode("utf-8"))
    else:
        folder = asset_folder(path)
        if report.figures:
            _replace_folder_atomic(folder, {f"{fig.name}.png": mark_png(fig.png) for fig in report.figures})
        write_bytes_atomic(path, (report.to_markdown(folder.name) + MARKDOWN_MARK).encode("utf-8"))
    return path


def check_report_path(path) -> str:
    """``"html"`` or ``"md"`` for a report path; :class:`ReportError` for another suffix (check it before
    a long computation)."""
    kind = report_kind(path)
    if kind is None:
        raise ReportError(f"report {path}: unknown suffix {Path(path).suffix!r}; use one of "
                          f"{', '.join(REPORT_SUFFIXES)}")
    return kind
