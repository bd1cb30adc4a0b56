"""Every command and code block of docs/*.md runs (see tests/docs/runner.py for the conventions),
every JSON the docs' commands write validates against its schema, links resolve, and the README
points to the docs."""
import re
import time

import pytest

from .jsonschema_lite import validate
from .runner import DOCS, ROOT, Workspace, match_output, parse_blocks, parse_console, run_doc, strict_json

#: pages whose commands take minutes (the loop on long simulated recordings): run with the slow tests
SLOW_PAGES = {"tutorial-diagnosis.md"}
PAGES = sorted(p.name for p in DOCS.glob("*.md"))
PAGE_PARAMS = [pytest.param(p, marks=pytest.mark.slow) if p in SLOW_PAGES else p for p in PAGES]


def _validate_json(path, schema_name, where):
    import json

    schema = json.loads((DOCS / "schemas" / f"{schema_name}.schema.json").read_text())
    errs = validate(strict_json(path), schema)
    assert not errs, f"{where}: {path.name} does not match schemas/{schema_name}.schema.json:\n" + "\n".join(errs[:20])


@pytest.mark.parametrize("page", PAGE_PARAMS)
def test_page_runs(page, tmp_path):
    ws = Workspace(tmp_path)
    t0 = time.perf_counter()
    log = run_doc(DOCS / page, ws, validate_json=_validate_json)
    dt = time.perf_counter() - t0
    print(f"{page}: {len(log.ran)} blocks/commands run in {dt:.1f} s")
    for s in log.ran:
        print("  ran:", s)
    for s in log.skipped:
        print("  not run:", s)
    if page.startswith("tutorial") or page in ("robot-file.md", "data-files.md", "command-line.md"):
        assert log.ran, f"{page}: nothing ran"


def test_readme_tour_runs(tmp_path):
    """The README's tour (its ```console and ```python blocks) runs like the docs."""
    ws = Workspace(tmp_path)
    log = run_doc(ROOT / "README.md", ws, validate_json=_validate_json)
    print(f"README.md: {len(log.ran)} blocks/commands run")
    for s in log.ran:
        print("  ran:", s)
    for s in log.skipped:
        print("  not run:", s)
    assert log.ran


def test_skips_are_explained_and_real_data_marked():
    """A block is skipped only with a reason; commands reading ../shared/data are marked realdata."""
    for md in [ROOT / "README.md"] + [DOCS / p for p in PAGES]:
        for b in parse_blocks(md):
            if "skip" in b.marks:
                assert b.marks["skip"] is not True, f"{b.where}: skip without a reason"
            if "shared/data" in b.text and b.lang in ("console", "python"):
                assert b.marks.get("realdata") or "skip" in b.marks, f"{b.where}: reads ../shared/data, mark it realdata"


def test_links_resolve():
    link = re.compile(r"\]\(([^)#\s]+)(#[^)]*)?\)")
    for md in [ROOT / "README.md"] + sorted(DOCS.glob("*.md")):
        for target, _ in link.findall(md.read_text()):
            if re.match(r"[a-z]+:", target):
                continue
            assert (md.parent / target).exists(), f"{md.relative_to(ROOT)}: broken link {target}"


def test_every_page_is_reachable_from_the_index_and_readme_points_to_docs():
    index = (DOCS / "README.md").read_text()
    for page in PAGES:
        if page != "README.md":
            assert f"({page}" in index, f"docs/README.md does not link {page}"
    readme = (ROOT / "README.md").read_text()
    assert "docs/README.md" in readme
    first = [ln for ln in readme.splitlines() if ln.startswith("make ")][:2]
    assert first[0].startswith("make demo") and first[1].startswith("make test")


# ---------------------------------------------------------------------------------------------
# the runner itself
# ---------------------------------------------------------------------------------------------
def test_output_matching():
    out = "a: 42 standard -> 25 base\nnoise\n  x = 1\nlast line\n"
    assert match_output(["a: ... standard -> 25 base", "...", "x = 1"], out) is None
    assert match_output(["x = 1", "a: 42 standard -> 25 base"], out) == "a: 42 standard -> 25 base"  # order
    assert match_output(["a: 43 standard -> 25 base"], out) is not None
    assert match_output(["last"], out) == "last"  # whole lines, not prefixes


def test_console_parsing(tmp_path):
    md = tmp_path / "x.md"
    md.write_text("text\n<!-- test: exit=2; realdata -->\n```console\n$ echo a \\\n  b\na b\n$ true\n```\n\n"
                  "<!-- test: file=f.txt -->\n```text\nhello\n```\n")
    b1, b2 = parse_blocks(md)
    assert b1.marks == {"exit": "2", "realdata": True} and b2.marks == {"file": "f.txt"}
    (c1, c2) = parse_console(b1)
    assert c1.cmd == "echo a b" and c1.expected == ["a b"] and c2.cmd == "true" and c2.expected == []


def test_runner_catches_a_rotten_page(tmp_path):
    """A wrong expected output, a failing command and a wrong exit status each fail the page."""
    ws = Workspace(tmp_path / "ws")
    for text in ("```console\n$ echo 1\n2\n```\n", "```console\n$ false\n```\n",
                 "<!-- test: exit=2 -->\n```console\n$ true\n```\n", "```python\nassert 1 == 2\n```\n",
                 "```bash\necho not run\n```\n"):
        md = tmp_path / "rot.md"
        md.write_text(text)
        with pytest.raises(AssertionError):
            run_doc(md, ws, validate_json=_validate_json)
