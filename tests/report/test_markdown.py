"""Markdown reports (images in ``<stem>_files/`` beside the text), atomic writing, and the ``identify
--report`` errors (unknown suffix, matplotlib missing)."""
import os
import re
import sys

import pytest

from symoro_gen.atomic import mark_png
from symoro_gen.errors import OutputError
from symoro_gen.report import (
    Figure,
    Heading,
    MissingDependencyError,
    Paragraph,
    Report,
    ReportError,
    Table,
    asset_folder,
    document,
    require_matplotlib,
)

from .pngcheck import decode_png, embedded_images, ink_stats

LINK_RE = re.compile(r"!\[[^\]]*\]\(([^)]+)\)")


def _md_table(md: str, first_header: str) -> list[list[str]]:
    """Rows (cells) of the first Markdown table whose header starts with ``| first_header |``."""
    lines = md.splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith(f"| {first_header} |"))
    rows = []
    for ln in lines[start + 2:]:
        if not ln.startswith("|"):
            break
        rows.append([c.strip() for c in ln.strip().strip("|").split(" | ")])
    return rows


def test_markdown_report_links_its_images_and_tables_match_the_json(rx90_md_report, rx90_html_report):
    path, res = rx90_md_report
    md = path.read_text(encoding="utf-8")
    folder = asset_folder(path)
    assert folder == path.parent / "report_files" and folder.is_dir()
    links = LINK_RE.findall(md)
    assert links == ["report_files/torque-identification-data.png", "report_files/torque-validation-data.png",
                     "report_files/singular-values.png"]
    assert sorted(p.name for p in folder.iterdir()) == sorted(os.path.basename(x) for x in links)
    html_imgs = embedded_images(rx90_html_report[0].read_text(encoding="utf-8"))
    for link, (png_html, w, h) in zip(links, html_imgs):
        png = (path.parent / link).read_bytes()
        rgb = decode_png(png)
        assert rgb.shape == (h, w, 3) and w == 1100
        assert ink_stats(rgb)[0] > 0.03
        assert png == png_html  # same data, same figure, byte for byte (deterministic PNG, no version text)
    # parameter table: one row per identified parameter, values as in the JSON contract
    p = res["parameters"]
    rows = _md_table(md, "Parameter")
    assert [r[0] for r in rows] == p["names"]
    for r, v, s, pct in zip(rows, p["values"], p["std"], p["rel_std_pct"]):
        assert float(r[1]) == pytest.approx(v, rel=6e-4, abs=1e-12)
        assert float(r[2]) == pytest.approx(2 * s, rel=6e-4)
        assert float(r[3]) == pytest.approx(pct, abs=0.006)
        assert (r[4] == "poorly identified") == (pct > 30)
    # relative error norms per joint, identification and validation (Table III)
    errs = {r[0]: [float(x) for x in r[1:]] for r in _md_table(md, "Data")}
    assert errs["identification (as fitted)"] == pytest.approx(res["rel_err"], abs=6e-5)
    assert errs["validation data"] == pytest.approx(res["validation"]["rel_err"], abs=6e-5)
    assert max(errs["validation data"]) < 0.1
    assert not [q for q in path.parent.iterdir() if q.name.startswith(".")]  # no temporary left


def _tiny_report(tag: str, png: bytes | None = None) -> Report:
    blocks = [Heading("Section"), Paragraph(f"text {tag} with | pipe and <b>tag</b>"),
              Table(("a", "b"), (("x|y", "1"),), caption="cap")]
    if png is not None:
        blocks.append(Figure("fig", png, "a figure"))
    return Report(f"Report {tag}", tuple(blocks))


def _png(w=7, h=5) -> bytes:
    """A small valid RGB PNG (independent of matplotlib)."""
    import struct
    import zlib

    raw = b"".join(b"\x00" + bytes([200, 30, 30]) * w for _ in range(h))

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def test_markdown_escapes_and_rewrites_the_image_folder(tmp_path):
    out = tmp_path / "sub" / "r.md"
    document.write_report_files(_tiny_report("one", _png()), out)
    md = out.read_text(encoding="utf-8")
    assert md.startswith("# Report one\n")
    assert "| x\\|y | 1 |" in md and "![a figure](r_files/fig.png)" in md
    assert (tmp_path / "sub" / "r_files" / "fig.png").read_bytes() == mark_png(_png())  # marked as symoro-gen's
    assert decode_png(mark_png(_png())).tolist() == decode_png(_png()).tolist()
    (tmp_path / "sub" / "r_files" / "stale.png").write_bytes(mark_png(_png(3, 3)))  # an earlier report's image
    document.write_report_files(_tiny_report("two", _png(9, 4)), out)
    assert sorted(p.name for p in (tmp_path / "sub" / "r_files").iterdir()) == ["fig.png"]
    assert (tmp_path / "sub" / "r_files" / "fig.png").read_bytes() == mark_png(_png(9, 4))
    # a file symoro-gen did not write in the image folder: the folder is not replaced without force
    (tmp_path / "sub" / "r_files" / "notes.txt").write_text("mine\n")
    with pytest.raises(OutputError, match=r"notes\.txt"):
        document.write_report_files(_tiny_report("two", _png(9, 4)), out)
    assert (tmp_path / "sub" / "r_files" / "notes.txt").read_text() == "mine\n"
    document.write_report_files(_tiny_report("two", _png(9, 4)), out, force=True)
    assert sorted(p.name for p in (tmp_path / "sub" / "r_files").iterdir()) == ["fig.png"]
    assert sorted(p.name for p in (tmp_path / "sub").iterdir()) == ["r.md", "r_files"]
    html = document.write_report_files(_tiny_report("three", _png()), tmp_path / "r.html").read_text()
    assert "&lt;b&gt;tag&lt;/b&gt;" in html and "<b>tag</b>" not in html
    assert 'width="7" height="5"' in html


def test_failed_write_leaves_the_previous_report_and_no_temporary(tmp_path, monkeypatch):
    out = tmp_path / "r.html"
    document.write_report_files(_tiny_report("old"), out)
    before = out.read_bytes()

    def boom(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", boom)  # the rename of symoro_gen.atomic
    with pytest.raises(OSError, match="disk full"):
        document.write_report_files(_tiny_report("new"), out)
    monkeypatch.undo()
    assert out.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.html"]


def test_unknown_suffix_and_bad_blocks_are_refused(tmp_path):
    with pytest.raises(ReportError, match=r"unknown suffix '\.pdf'"):
        document.write_report_files(_tiny_report("x"), tmp_path / "r.pdf")
    with pytest.raises(ValueError, match="row 0 has 1 cells for 2 columns"):
        Table(("a", "b"), (("x",),))
    with pytest.raises(ValueError, match="not a PNG"):
        Figure("f", b"GIF89a....")
    with pytest.raises(ValueError, match="duplicate figure names"):
        Report("t", (Figure("f", _png()), Figure("f", _png())))
    assert not list(tmp_path.iterdir())


def _hide_matplotlib(monkeypatch):
    for name in ("matplotlib", "matplotlib.figure", "matplotlib.backends", "matplotlib.backends.backend_agg"):
        monkeypatch.setitem(sys.modules, name, None)  # import raises ImportError


def test_missing_matplotlib_names_the_extra(monkeypatch, tmp_path, cli):
    from symoro_gen.workflows.reporting import ReportContent, build_report

    _hide_matplotlib(monkeypatch)
    with pytest.raises(MissingDependencyError, match="'plots' extra") as exc:
        require_matplotlib()
    assert "symoro_gen[plots]" in exc.value.hint
    # the command fails at once (before loading any data), one line and the hint, status 2
    err = cli("identify", "rx90", tmp_path / "absent.csv", "--report", tmp_path / "r.html", rc=2).err
    assert "'plots' extra" in err and "hint: pip install 'symoro_gen[plots]'" in err
    assert not list(tmp_path.iterdir())
    # tables alone need no matplotlib
    rep = build_report(None, content=ReportContent(title="t", plots=False, notes=["n"]))
    assert rep.figures == () and "<li>n</li>" in rep.to_html()


def test_identify_refuses_an_unknown_report_suffix(tmp_path, cli):
    err = cli("identify", "rx90", tmp_path / "absent.csv", "--report", tmp_path / "r.pdf", rc=2).err
    assert "unknown suffix '.pdf'" in err
