"""Import layout of the stages: observations -> identification -> diagnostics, no import circle.

Each module is imported alone in a fresh interpreter (a circle shows up as an ImportError on a partially
initialised module in one of them), and no module hides an import inside a function (the habit that hid
the circles), apart from the command-line modules, which import lazily on purpose."""
from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

import symoro_gen

PKG = Path(symoro_gen.__file__).resolve().parent
PACKAGES = ("observations", "identification", "diagnostics")
#: modules allowed to import inside functions (command-line entry points, imported by symoro_gen.cli)
LAZY_OK = {"identification/cli.py", "diagnostics/cli.py"}


def _modules():
    for pkg in PACKAGES:
        for f in sorted((PKG / pkg).glob("*.py")):
            name = f"symoro_gen.{pkg}" if f.stem == "__init__" else f"symoro_gen.{pkg}.{f.stem}"
            yield name, f


@pytest.mark.parametrize("name", [n for n, _ in _modules()])
def test_module_imports_alone_in_a_fresh_interpreter(name):
    r = subprocess.run([sys.executable, "-c", f"import {name}"], capture_output=True, text=True,
                       cwd=PKG.parent, timeout=300, check=False)
    assert r.returncode == 0, r.stderr[-2000:]


def _own_import(node) -> bool:
    """An import of this package's own modules (what hides a circle); a lazy import of a heavy optional
    third-party package (scikit-learn, matplotlib...) inside a function is allowed."""
    if isinstance(node, ast.ImportFrom):
        return node.level > 0 or (node.module or "").split(".")[0] == "symoro_gen"
    if isinstance(node, ast.Import):
        return any(a.name.split(".")[0] == "symoro_gen" for a in node.names)
    return False


def test_no_function_local_imports():
    found = []
    for name, f in _modules():
        rel = f.relative_to(PKG).as_posix()
        if rel in LAZY_OK:
            continue
        tree = ast.parse(f.read_text())
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                for sub in ast.walk(node):
                    if _own_import(sub):
                        found.append(f"{rel}:{sub.lineno}")
    assert not found, f"function-local imports (hide import circles): {found}"


def test_observations_do_not_import_later_stages():
    """The assembly stage stands alone: importing it loads neither identification nor diagnostics."""
    code = ("import sys, symoro_gen.observations; "
            "print(sorted(m for m in sys.modules if m.startswith(('symoro_gen.identification', "
            "'symoro_gen.diagnostics'))))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=PKG.parent, timeout=300,
                       check=False)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.strip() == "[]", r.stdout
