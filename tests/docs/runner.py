"""Run the documentation: every command and code block of ``docs/*.md`` is executed, in order, in a
scratch copy of the repository's layout, so the docs cannot rot.

Markdown conventions (see ``docs/README.md``)
---------------------------------------------
* ```` ```console ```` blocks: lines starting with ``$ `` are shell commands (a trailing ``\\``
  continues a command on the next line); the lines after a command, up to the next ``$ ``, are its
  expected output. Each expected line must match one line of the actual output (stdout and stderr
  merged), in order, after stripping blanks; ``...`` inside a line matches anything, a line that
  is only ``...`` stands for lines left out. A command must exit with status 0 unless marked.
* ```` ```python ```` blocks run as standalone scripts (``python block.py``): every block has its
  own imports; they may ``assert``.
* An HTML comment on the line before a block marks it (invisible on GitHub)::

      <!-- test: skip=REASON -->     not run (the reason is required)
      <!-- test: realdata -->        needs ../shared/data (skipped when absent)
      <!-- test: exit=2 -->          the command(s) must exit with this status
      <!-- test: needs=diagnose -->  needs that symoro-gen command (skipped, reported pending, until it lands)
      <!-- test: module=matplotlib --> needs that Python module (an optional extra)
      <!-- test: file=PATH -->       the block's text is written to PATH (a robot file, a URDF...)
      <!-- test: output -->          expected output of the preceding python block (same matching rules)
      <!-- test: schema=identify --> the JSON written by the command's --json must validate against
                                     docs/schemas/identify.schema.json

  Several marks are separated by ``;``.

The scratch workspace mirrors a checkout: ``robots/`` (a copy), ``docs/`` (a link), ``generated/`` (a copy, where
``symoro-gen generate`` writes: ``SYMORO_GENERATED``), ``../shared/data`` (a link to the real
recordings when present), and ``symoro-gen`` / ``python`` on ``PATH`` running this checkout.
Generated models use the NumPy backend there (``SYMORO_BACKEND=numpy``): compiling the C kernels
of every model a page generates would take most of the time budget.
"""
from __future__ import annotations

import contextlib
import importlib.util
import io
import itertools
import json
import os
import re
import runpy
import shlex
import shutil
import subprocess
import sys
import time
import traceback
import warnings
from dataclasses import dataclass, field
from pathlib import Path

from tests.conftest import find_shared_data

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
SHARED_DATA = find_shared_data()  # the real recordings (tests/conftest.py: one place that locates them)
RUNNABLE = ("console", "python")
SHELL_LANGS = ("sh", "bash", "shell", "zsh")
_MARK_RE = re.compile(r"^\s*<!--\s*test:\s*(.*?)\s*-->\s*$")
_FENCE_RE = re.compile(r"^(\s*)(`{3,})\s*([\w+-]*)\s*(.*)$")


@dataclass
class Block:
    """One fenced block of a Markdown file."""

    doc: Path
    line: int  # 1-based line of the opening fence
    lang: str
    text: str
    marks: dict = field(default_factory=dict)

    @property
    def where(self) -> str:
        doc = self.doc.relative_to(ROOT) if self.doc.is_relative_to(ROOT) else self.doc
        return f"{doc}:{self.line}"


def parse_marks(text: str) -> dict:
    marks: dict = {}
    for item in (x.strip() for x in text.split(";")):
        if not item:
            continue
        k, _, v = item.partition("=")
        marks[k.strip()] = v.strip() if _ else True
    return marks


def parse_blocks(path: Path) -> list[Block]:
    """The fenced blocks of ``path`` with the marks of the comment just before each."""
    lines = path.read_text(encoding="utf-8").splitlines()
    blocks: list[Block] = []
    i = 0
    pending: dict = {}
    while i < len(lines):
        m = _MARK_RE.match(lines[i])
        if m:
            pending = parse_marks(m.group(1))
            i += 1
            continue
        f = _FENCE_RE.match(lines[i])
        if f:
            fence, lang = f.group(2), f.group(3).lower()
            start = i
            body = []
            i += 1
            while i < len(lines) and not lines[i].strip().startswith(fence):
                body.append(lines[i])
                i += 1
            blocks.append(Block(path, start + 1, lang, "\n".join(body) + "\n", pending))
            pending = {}
            i += 1
            continue
        if lines[i].strip():
            pending = {}  # a mark applies to the block right after it only
        i += 1
    return blocks


@dataclass
class Command:
    cmd: str
    expected: list[str]
    line: int


def parse_console(block: Block) -> list[Command]:
    """Commands (``$ ``) of a console block with their expected output lines."""
    cmds: list[Command] = []
    lines = block.text.splitlines()
    i = 0
    while i < len(lines):
        ln = lines[i]
        if ln.startswith("$ "):
            cmd = ln[2:]
            start = i
            while cmd.endswith("\\") and i + 1 < len(lines):
                i += 1
                cmd = cmd[:-1].rstrip() + " " + lines[i].strip()
            cmds.append(Command(cmd, [], block.line + 1 + start))
        elif cmds:
            cmds[-1].expected.append(ln)
        elif ln.strip():
            raise AssertionError(f"{block.where}: console block text before the first `$ ` command: {ln!r}")
        i += 1
    return cmds


def _line_regex(expected: str) -> re.Pattern:
    parts = [re.escape(p) for p in expected.strip().split("...")]
    return re.compile(".*".join(parts))


def match_output(expected: list[str], actual: str) -> str | None:
    """None when every expected line matches an actual line, in order; else what is missing."""
    act = [a.strip() for a in actual.splitlines()]
    k = 0
    for e in expected:
        e = e.strip()
        if not e or e == "...":
            continue
        rx = _line_regex(e)
        while k < len(act) and not rx.fullmatch(act[k]):
            k += 1
        if k == len(act):
            return e
        k += 1
    return None


_ROBOT_OUT_RE = re.compile(r"(?:^|\s)(?:-o|--output|--out|>)\s*robots/([A-Za-z_][A-Za-z0-9_]*)\.toml(?=\s|$)")


def robots_the_docs_create() -> set[str]:
    """Names of the robot files the docs (``docs/*.md``, README.md) write into ``robots/``:
    ``<!-- test: file=robots/NAME.toml -->`` blocks and commands writing ``-o robots/NAME.toml``.

    A user who followed the tutorials has them in the checkout already; the docs' workspace starts
    without them (and their generated packages), as the pages assume.
    """
    names: set[str] = set()
    for page in sorted(DOCS.glob("*.md")) + [ROOT / "README.md"]:
        if not page.is_file():
            continue
        for b in parse_blocks(page):
            f = str(b.marks.get("file", ""))
            if f.startswith("robots/") and f.endswith(".toml"):
                names.add(Path(f).stem)
            if b.lang == "console":
                for c in parse_console(b):
                    names |= set(_ROBOT_OUT_RE.findall(c.cmd))
    return names


class Workspace:
    """A scratch checkout layout with ``symoro-gen`` and ``python`` on PATH.

    ``robots/`` and ``generated/`` are those of the checkout (robots a user added included: the
    pages must hold for them), minus the robots the docs themselves create
    (:func:`robots_the_docs_create`), which a user who followed the tutorials already has.
    """

    def __init__(self, base: Path):
        self.base = base
        self.cwd = base / "repo"
        self.cwd.mkdir(parents=True)
        created = robots_the_docs_create()
        shutil.copytree(ROOT / "robots", self.cwd / "robots",
                        ignore=lambda d, names: [n for n in names if n.endswith(".toml") and n[:-5] in created])
        (self.cwd / "docs").symlink_to(DOCS)  # read only: the schemas
        top = str(ROOT / "generated")
        shutil.copytree(ROOT / "generated", self.cwd / "generated",
                        ignore=lambda d, names: [n for n in names if n == "__pycache__" or n.startswith(".")
                                                 or (d == top and n in created)])
        if SHARED_DATA.is_dir():
            (base / "shared").mkdir()
            (base / "shared" / "data").symlink_to(SHARED_DATA)
        bin_ = base / "bin"
        bin_.mkdir()
        py = shlex.quote(sys.executable)
        for name, line in (("symoro-gen", f'exec {py} -m symoro_gen "$@"'), ("python", f'exec {py} "$@"'),
                           ("python3", f'exec {py} "$@"')):
            p = bin_ / name
            p.write_text(f"#!/bin/sh\n{line}\n")
            p.chmod(0o755)
        self.env = dict(os.environ)
        self.env.update(
            PATH=f"{bin_}{os.pathsep}{os.environ.get('PATH', '')}",
            PYTHONPATH=str(ROOT),
            SYMORO_GENERATED=str(self.cwd / "generated"),
            SYMORO_ROBOTS=str(self.cwd / "robots"),
            OPENBLAS_NUM_THREADS="1",
            MPLBACKEND="Agg",
            SYMORO_BACKEND="numpy",  # no C compilation of each model the docs generate (the C kernels are tested elsewhere)
            COLUMNS="120",
        )
        self.env.pop("SYMORO_PROGRESS", None)
        self.n_py = 0

    @property
    def has_data(self) -> bool:
        return (self.base / "shared" / "data").is_dir()

    def sh(self, cmd: str, timeout: float) -> subprocess.CompletedProcess:
        argv = _plain_symoro_gen(cmd)
        if argv is not None and not SUBPROCESS_ONLY:
            return self._in_process(lambda: _run_main(argv), cmd)
        return subprocess.run(["bash", "-c", cmd], cwd=self.cwd, env=self.env, stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, text=True, timeout=timeout)

    def python(self, code: str, timeout: float) -> subprocess.CompletedProcess:
        self.n_py += 1
        f = self.base / f"doc_block_{self.n_py}.py"
        f.write_text(code)
        if not SUBPROCESS_ONLY:
            return self._in_process(lambda: _run_script(f), str(f))
        return subprocess.run([sys.executable, str(f)], cwd=self.cwd, env=self.env, stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, text=True, timeout=timeout)

    def _in_process(self, fn, what: str) -> subprocess.CompletedProcess:
        """Run ``fn() -> status`` here, as the subprocess would: in the workspace, with its
        environment, stdout and stderr merged, warnings printed (not recorded by pytest)."""
        buf = io.StringIO()
        old_cwd, old_env, old_argv = os.getcwd(), dict(os.environ), sys.argv[:]
        os.chdir(self.cwd)
        os.environ.clear()
        os.environ.update(self.env)
        try:
            with warnings.catch_warnings(), contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):
                warnings.simplefilter("default")
                warnings.showwarning = _print_warning
                status = fn()
        finally:
            os.chdir(old_cwd)
            os.environ.clear()
            os.environ.update(old_env)
            sys.argv[:] = old_argv
        return subprocess.CompletedProcess(what, status, buf.getvalue(), None)


#: run every command and block in a subprocess (slower, closest to a user's shell): SYMORO_DOCS_SUBPROCESS=1
SUBPROCESS_ONLY = os.environ.get("SYMORO_DOCS_SUBPROCESS", "") == "1"
_SHELL_CHARS = set("|&;<>$`*?()[]{}~!#\\'\"\n")


def _plain_symoro_gen(cmd: str) -> list[str] | None:
    """The arguments of ``cmd`` when it is a plain ``symoro-gen ...`` call the test can run in this
    process (no pipes, redirections, variables or globs: those go through the shell)."""
    try:
        toks = shlex.split(cmd)
    except ValueError:
        return None
    if not toks or toks[0] != "symoro-gen":
        return None
    # quoted arguments are fine (a spec string); shell syntax outside quotes is not
    unquoted = re.sub(r"'[^']*'|\"[^\"]*\"", "", cmd)
    if set(unquoted) & _SHELL_CHARS or "$" in cmd or re.match(r"^\w+=", cmd):
        return None
    return toks[1:]


def _run_main(argv: list[str]) -> int:
    from symoro_gen.cli import main

    try:
        return int(main(argv) or 0)
    except SystemExit as exc:  # argparse: --help, usage errors
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)


def _run_script(path: Path) -> int:
    sys.argv[:] = [str(path)]
    try:
        runpy.run_path(str(path), run_name="__main__")
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except Exception:  # noqa: BLE001 - the block's failure is the test's report
        traceback.print_exc()
        return 1
    return 0


def _print_warning(message, category, filename, lineno, file=None, line=None) -> None:
    sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))


def available_commands() -> set[str]:
    import argparse

    from symoro_gen.cli import build_parser

    (sub,) = [a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    return set(sub.choices)


def json_out_of(cmd: str) -> str | None:
    toks = shlex.split(cmd)
    for a, b in itertools.pairwise(toks):
        if a == "--json":
            return b
    return None


@dataclass
class RunLog:
    ran: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)


def run_doc(path: Path, ws: Workspace, *, validate_json, timeout: float = 300.0) -> RunLog:
    """Run every block of ``path`` in ``ws``; raise AssertionError at the first failure."""
    log = RunLog()
    commands = available_commands()
    last_py_out: str | None = None
    for b in parse_blocks(path):
        marks = b.marks
        if b.lang in SHELL_LANGS:
            raise AssertionError(f"{b.where}: use ```console (with `$ ` prompts) so the test runs it, not ```{b.lang}")
        if "skip" in marks:
            if marks["skip"] is True or not str(marks["skip"]).strip():
                raise AssertionError(f"{b.where}: `test: skip` needs a reason (skip=...)")
            log.skipped.append(f"{b.where}: skip ({marks['skip']})")
            continue
        if marks.get("realdata") and not ws.has_data:
            log.skipped.append(f"{b.where}: real data absent ({SHARED_DATA})")
            last_py_out = None
            continue
        mod = marks.get("module")
        if mod and importlib.util.find_spec(mod) is None:
            log.skipped.append(f"{b.where}: needs the Python module {mod}")
            last_py_out = None
            continue
        need = marks.get("needs")
        if need and need not in commands:
            log.skipped.append(f"{b.where}: pending (`symoro-gen {need}` is not there yet)")
            last_py_out = None
            continue
        if "file" in marks:
            dst = ws.cwd / marks["file"]
            dst.parent.mkdir(parents=True, exist_ok=True)
            dst.write_text(b.text)
            log.ran.append(f"{b.where}: wrote {marks['file']}")
            continue
        if marks.get("output"):
            if last_py_out is None:
                raise AssertionError(f"{b.where}: `test: output` block without a python block run before it")
            miss = match_output(b.text.splitlines(), last_py_out)
            if miss is not None:
                raise AssertionError(f"{b.where}: expected output line not found: {miss!r}\n--- actual ---\n{last_py_out}")
            continue
        if b.lang == "python":
            t0 = time.perf_counter()
            r = ws.python(b.text, timeout)
            if r.returncode != 0:
                raise AssertionError(f"{b.where}: python block failed (status {r.returncode}):\n{r.stdout}")
            last_py_out = r.stdout
            log.ran.append(f"{b.where}: python ({time.perf_counter() - t0:.1f} s)")
            continue
        if b.lang != "console":
            continue
        want = int(marks.get("exit", 0))
        validated = 0
        for c in parse_console(b):
            t0 = time.perf_counter()
            r = ws.sh(c.cmd, timeout)
            if r.returncode != want:
                raise AssertionError(f"{b.where} (line {c.line}): `{c.cmd}` exited {r.returncode}, expected {want}:\n"
                                     f"{r.stdout}")
            miss = match_output(c.expected, r.stdout)
            if miss is not None:
                raise AssertionError(f"{b.where} (line {c.line}): `{c.cmd}`: expected output line not found: "
                                     f"{miss!r}\n--- actual ---\n{r.stdout}")
            out = json_out_of(c.cmd) if marks.get("schema") else None
            if out is not None:
                validate_json(ws.cwd / out, marks["schema"], f"{b.where} (line {c.line})")
                validated += 1
            log.ran.append(f"{b.where} (line {c.line}): {c.cmd[:70]} ({time.perf_counter() - t0:.1f} s)")
        if marks.get("schema") and not validated:
            raise AssertionError(f"{b.where}: `schema=` mark but no command of the block writes --json")
        last_py_out = None
    return log


def strict_json(path: Path):
    """Parse JSON refusing NaN/Infinity (not JSON)."""

    def bad(x):
        raise ValueError(f"{path}: {x} is not valid JSON")

    return json.loads(Path(path).read_text(), parse_constant=bad)
