"""Import layout of the package: no import circle, no hidden function-local imports, light entry points;
no private name imported across modules; short functions with few parameters.

Every module of ``symoro_gen`` is imported alone, as the first module of the package, in a fresh
interpreter state (a circle shows up as an ImportError on a partially initialised module for some entry
point, and only for that one). No module hides an import of the package's own modules inside a function
(the habit that hid the circles) except the ones listed in ``LAZY_OK`` with their reason; lazy imports of
heavy optional third-party packages (matplotlib, casadi, scikit-learn, tqdm) are allowed anywhere.

The library's layout as well: the commands are leaves (one module each, imported by no module), the report
toolkit imports no stage, recordings are read only through the readers; mypy is not switched off; no issue
numbers in the source. Every check walks the installed package, ``symoro_gen/``, only (not bench/, research/
or tests/)."""
from __future__ import annotations

import ast
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

import symoro_gen

PKG = Path(symoro_gen.__file__).resolve().parent

#: function-local imports of the package's own modules that are kept on purpose:
#: file -> {imported module (as written, without leading dots): reason}
LAZY_OK: dict[str, dict[str, str]] = {
    # the command-line entry points: `symoro-gen --help` and the light commands start without sympy/scipy
    "cli.py": {"*": "lazy sub-command registration and generation stack (see the comment in cli.py)"},
    # `import symoro_gen` and every generated package stay free of sympy (test_light_entry_points)
    "loader.py": {"description": "sympy", "description.model": "sympy", "emit.package": "sympy",
                  "closedloop": "sympy (closed-loop robots only)",
                  "runtime.floating": "sympy (floating-base robots only)"},
}


def _modules() -> list[tuple[str, Path]]:
    out = []
    for f in sorted(PKG.rglob("*.py")):
        parts = f.relative_to(PKG.parent).with_suffix("").parts
        if parts[-1] == "__main__":
            continue  # runs the CLI when imported
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out.append((".".join(parts), f))
    return out


def test_every_module_imports_alone_without_a_circle():
    """One interpreter, and for each module: forget every ``symoro_gen`` module, import that one first.
    Third-party packages stay loaded (they cannot take part in a circle of ours), which keeps this fast."""
    names = [n for n, _ in _modules()]
    assert len(names) > 50, names  # the walk found the package
    code = (
        "import importlib, json, sys, traceback\n"
        f"names = {names!r}\n"
        "bad = {}\n"
        "for n in names:\n"
        "    for m in [m for m in sys.modules if m == 'symoro_gen' or m.startswith('symoro_gen.')]:\n"
        "        del sys.modules[m]\n"
        "    try:\n"
        "        importlib.import_module(n)\n"
        "    except Exception:\n"
        "        bad[n] = traceback.format_exc(limit=-3)\n"
        "print(json.dumps(bad))\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=PKG.parent, timeout=600,
                       check=False)
    assert r.returncode == 0, r.stderr[-2000:]
    bad = json.loads(r.stdout.strip().splitlines()[-1])
    assert not bad, "\n".join(f"{n}:\n{tb}" for n, tb in bad.items())


@pytest.mark.parametrize("name", ["symoro_gen.observations", "symoro_gen.identification", "symoro_gen.diagnostics",
                                  "symoro_gen.report", "symoro_gen.cli"])
def test_stage_imports_alone_in_a_fresh_interpreter(name):
    """The stages' entry points in a really fresh interpreter (third-party packages not loaded either)."""
    r = subprocess.run([sys.executable, "-c", f"import {name}"], capture_output=True, text=True,
                       cwd=PKG.parent, timeout=300, check=False)
    assert r.returncode == 0, r.stderr[-2000:]


def _own_import(node: ast.AST) -> str | None:
    """The module name (without leading dots) of an import of this package's own modules, else None; a
    lazy import of a heavy optional third-party package (scikit-learn, matplotlib...) is not one."""
    if isinstance(node, ast.ImportFrom):
        mod = node.module or ""
        if node.level > 0:
            return mod
        if mod.split(".")[0] == "symoro_gen":
            return mod.partition(".")[2]
    if isinstance(node, ast.Import):
        for a in node.names:
            if a.name.split(".")[0] == "symoro_gen":
                return a.name.partition(".")[2]
    return None


def test_no_function_local_imports():
    found = []
    for _, f in _modules():
        rel = f.relative_to(PKG).as_posix()
        allowed = LAZY_OK.get(rel, {})
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                for sub in ast.walk(node):
                    mod = _own_import(sub)
                    if mod is not None and "*" not in allowed and mod not in allowed:
                        found.append(f"{rel}:{sub.lineno} ({mod})")
    assert not found, f"function-local imports (hide import circles): {found}"


# ------------------------------------------------------------------------------------------------
# The import graph read from the source (every import of the package's own modules, at any depth: module
# level and inside functions alike; ``if TYPE_CHECKING:`` imports are left out, they never run).
# ------------------------------------------------------------------------------------------------

#: import edges left out of the circle check, each closing a circle through files of work in progress:
#: (importer, imported) -> reason. Remove an entry when its edge is gone (test_allow_lists_are_current).
CIRCLE_EDGES_OK: dict[tuple[str, str], str] = {
    # the command line: `symoro_gen.cli` registers the sub-commands lazily and the sub-command modules take
    # OptionError from it and their data options from preprocessing.cli (cli.py and */cli.py are being
    # reworked: OptionError and the shared data options want a home of their own)
}

#: private names imported across modules, in files of work in progress: (importer, source, name) -> reason.
#: Remove an entry when the import is gone (test_allow_lists_are_current).
PRIVATE_IMPORTS_OK: dict[tuple[str, str, str], str] = {
}


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _run_time_imports(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    """Every import statement of a module except those under ``if TYPE_CHECKING:``."""
    out: list[ast.Import | ast.ImportFrom] = []

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and _is_type_checking(node.test):
            for sub in node.orelse:
                visit(sub)
            return
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            out.append(node)
        for sub in ast.iter_child_nodes(node):
            visit(sub)

    visit(tree)
    return out


def _absolute(module: str, is_package: bool, node: ast.ImportFrom) -> str:
    """The absolute module name an ``from ... import`` reads from."""
    if not node.level:
        return node.module or ""
    base = module.split(".") if is_package else module.split(".")[:-1]
    base = base[:len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _add(lines: list[str], where: str) -> None:
    if where not in lines:
        lines.append(where)


def _import_graph(files: dict[str, Path] | None = None, root: Path | None = None
                  ) -> tuple[dict[str, dict[str, list[str]]], list[tuple]]:
    """``(edges, private)``: ``edges[a][b]`` lists the lines (``file:line``) where module ``a`` imports module
    ``b`` of the package; ``private`` the ``(importer, source, name, where)`` of every private name (one
    leading underscore) imported from another module of the package.

    ``from package import name`` counts as an import of ``package.name`` when that is a module, else of
    ``package``. Importing ``a.b.c`` also runs the ``__init__`` of ``a`` and ``a.b``: those are not counted,
    or a package whose ``__init__`` re-exports its modules would make every sibling import a circle."""
    files = dict(_modules()) if files is None else files
    root = PKG.parent if root is None else root
    edges: dict[str, dict[str, list[str]]] = {m: {} for m in files}
    private: list[tuple] = []
    for mod, f in files.items():
        rel = f.relative_to(root).as_posix()
        for node in _run_time_imports(ast.parse(f.read_text())):
            where = f"{rel}:{node.lineno}"
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names if a.name.split(".")[0] == "symoro_gen"]
                for t in targets:
                    if t in files and t != mod:
                        _add(edges[mod].setdefault(t, []), where)
                continue
            src = _absolute(mod, f.name == "__init__.py", node)
            if src.split(".")[0] != "symoro_gen":
                continue
            for a in node.names:
                target = f"{src}.{a.name}" if f"{src}.{a.name}" in files else src
                if target in files and target != mod:
                    _add(edges[mod].setdefault(target, []), where)
                if a.name.startswith("_") and not a.name.startswith("__") and target != mod:
                    private.append((mod, src, a.name, where))
    return edges, private


def _circles(edges: dict[str, dict[str, list[str]]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def connect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in edges.get(v, {}):
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            connect(v)
    return out


def _circle_report(edges: dict[str, dict[str, list[str]]]) -> list[str]:
    """One line per import inside each circle (the lines to cut one of)."""
    lines = []
    for comp in _circles(edges):
        inside = set(comp)
        lines.append("circle: " + " <-> ".join(comp))
        lines += [f"    {a} -> {b} ({', '.join(w)})" for a in comp for b, w in sorted(edges[a].items()) if b in inside]
    return lines


def _without(edges: dict[str, dict[str, list[str]]], allowed) -> dict[str, dict[str, list[str]]]:
    return {a: {b: w for b, w in bs.items() if (a, b) not in allowed} for a, bs in edges.items()}


def test_no_import_circle_counting_function_level_imports():
    """No module imports, even from inside a function, a module that imports it back (directly or through
    others): the module-level order of imports then decides whether the package can be imported, and a
    lazy import only hides the circle until someone moves it."""
    edges, _ = _import_graph()
    assert sum(len(b) for b in edges.values()) > 200, "the walk found the package's imports"
    report = _circle_report(_without(edges, CIRCLE_EDGES_OK))
    assert not report, "import circles:\n" + "\n".join(report)


def test_no_private_name_imported_from_another_module():
    """A name with a leading underscore is its module's business: another module that needs it needs a
    public name (in that module, or in a module both can import)."""
    _, private = _import_graph()
    found = [f"{where}: {imp} imports {name} from {src}" for imp, src, name, where in private
             if (imp, src, name) not in PRIVATE_IMPORTS_OK]
    assert not found, "private names imported across modules:\n" + "\n".join(found)


def test_allow_lists_are_current():
    """Every allowed circle edge and private import still exists (remove the entries the rework has made
    unnecessary: the lists only shrink)."""
    edges, private = _import_graph()
    stale = [f"edge {a} -> {b}" for a, b in CIRCLE_EDGES_OK if b not in edges.get(a, {})]
    seen = {(imp, src, name) for imp, src, name, _ in private}
    stale += [f"private {name} of {src} in {imp}" for imp, src, name in PRIVATE_IMPORTS_OK
              if (imp, src, name) not in seen]
    assert not stale, "allow-list entries no longer needed: " + "; ".join(stale)


def test_the_checks_see_a_circle_and_a_private_import(tmp_path):
    """The checks themselves: a package of three modules with a circle through a function-level import
    (and one under ``if TYPE_CHECKING:``, which does not count), and a private import."""
    pkg = tmp_path / "symoro_gen"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from .b import f\n")
    (pkg / "b.py").write_text("def f():\n    from symoro_gen.c import _g\n    return _g\n")
    (pkg / "c.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from . import b\n"
                              "def _g():\n    from . import a\n")
    files = {"symoro_gen": pkg / "__init__.py", **{f"symoro_gen.{m}": pkg / f"{m}.py" for m in "abc"}}
    edges, private = _import_graph(files, root=tmp_path)
    assert edges["symoro_gen.c"] == {"symoro_gen.a": ["symoro_gen/c.py:5"]}   # the TYPE_CHECKING one left out
    assert _circles(edges) == [["symoro_gen.a", "symoro_gen.b", "symoro_gen.c"]]
    assert [p[:3] for p in private] == [("symoro_gen.b", "symoro_gen.c", "_g")]
    assert not _circles(_without(edges, {("symoro_gen.b", "symoro_gen.c")}))


def _functions() -> list[tuple[str, ast.FunctionDef | ast.AsyncFunctionDef]]:
    out = []
    for mod, f in _modules():
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                out.append((mod, node))
    return out


def _n_parameters(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    a = fn.args
    n = len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + (a.vararg is not None) + (a.kwarg is not None)
    first = (a.posonlyargs + a.args)[:1]
    return n - (1 if first and first[0].arg in ("self", "cls") else 0)


#: functions longer than MAX_FUNCTION_LINES or with more than MAX_PARAMETERS parameters (self and cls not
#: counted), in files of work in progress: "module:function" -> reason. Remove an entry when it holds.
SIZE_OK: dict[str, str] = {}
MAX_FUNCTION_LINES = 120
MAX_PARAMETERS = 12


def _oversized() -> dict[str, str]:
    out = {}
    for mod, fn in _functions():
        lines = fn.end_lineno - fn.lineno + 1 if fn.end_lineno is not None else 0
        n = _n_parameters(fn)
        if lines > MAX_FUNCTION_LINES or n > MAX_PARAMETERS:
            out[f"{mod}:{fn.name}"] = f"{lines} lines, {n} parameters"
    return out


def test_functions_are_short_and_take_few_parameters():
    """No function over MAX_FUNCTION_LINES lines (docstring included) and no signature over MAX_PARAMETERS
    parameters (options that belong together are one dataclass, or one typed group of keywords)."""
    big = _oversized()
    found = [f"{k}: {v}" for k, v in sorted(big.items()) if k not in SIZE_OK]
    assert not found, "\n".join(found)
    stale = [k for k in SIZE_OK if k not in big]
    assert not stale, f"SIZE_OK entries no longer needed: {stale}"


def test_lazy_ok_lists_only_existing_files():
    """The allow-list stays true: every file it names exists, and still imports lazily every module it names."""
    missing = [rel for rel in LAZY_OK if not (PKG / rel).is_file()]
    assert not missing, missing
    stale = []
    for rel, allowed in LAZY_OK.items():
        lazy = {mod for node in ast.walk(ast.parse((PKG / rel).read_text()))
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
                for sub in ast.walk(node) if (mod := _own_import(sub)) is not None}
        stale += [f"{rel}: {mod}" for mod in allowed if mod != "*" and mod not in lazy]
    assert not stale, f"LAZY_OK entries no longer needed: {stale}"


def _loaded(code: str) -> list[str]:
    r = subprocess.run([sys.executable, "-c", code + "\nimport sys, json\n"
                        "print(json.dumps(sorted(m for m in sys.modules if '.' not in m)))"],
                       capture_output=True, text=True, cwd=PKG.parent, timeout=300, check=False)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_light_entry_points():
    """Why loader.py and cli.py import lazily: the package, the command line and a generated package load
    neither sympy nor scipy (a generated package is plain NumPy; importing it compiles nothing)."""
    for code in ("import symoro_gen", "import symoro_gen.cli", "import symoro_gen.runtime"):
        heavy = {"sympy", "scipy", "matplotlib", "sklearn"} & set(_loaded(code))
        assert not heavy, f"{code!r} loads {sorted(heavy)}"
    gen = PKG.parent / "generated" / "scara"
    if not (gen / "__init__.py").is_file():
        pytest.skip("generated/scara is absent (run `symoro-gen generate scara`)")
    mods = _loaded(f"import sys; sys.path.insert(0, {str(gen.parent)!r}); import scara")
    assert not {"sympy", "scipy"} & set(mods), mods


def test_observations_do_not_import_later_stages():
    """The assembly stage stands alone: importing it loads neither identification nor diagnostics."""
    code = ("import sys, symoro_gen.observations; "
            "print(sorted(m for m in sys.modules if m.startswith(('symoro_gen.identification', "
            "'symoro_gen.diagnostics'))))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=PKG.parent, timeout=300,
                       check=False)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.strip() == "[]", r.stdout


# ------------------------------------------------------------------------------------------------
# The library's layout: commands are leaves, one reader, a generic report toolkit.
# ------------------------------------------------------------------------------------------------

def _reachable(edges: dict[str, dict[str, list[str]]], start: str) -> dict[str, str]:
    """Every module ``start`` imports, directly or through others: module -> the module that imports it."""
    seen: dict[str, str] = {}
    todo = [start]
    while todo:
        a = todo.pop()
        for b in edges.get(a, {}):
            if b not in seen and b != start:
                seen[b] = a
                todo.append(b)
    return seen


def _registered_commands() -> dict[str, str]:
    """``command -> module`` of the sub-commands ``cli.py`` registers (its ``_leaf("<module>")`` calls in the
    ``_COMMANDS`` mapping), read from the source."""
    tree = ast.parse((PKG / "cli.py").read_text())
    out = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            for k, v in zip(node.keys, node.values):
                if (isinstance(k, ast.Constant) and isinstance(v, ast.Call) and isinstance(v.func, ast.Name)
                        and v.func.id == "_leaf" and isinstance(v.args[0], ast.Constant)):
                    out[str(k.value)] = str(v.args[0].value)
    return out


def test_commands_are_leaves_one_module_per_command():
    """``symoro_gen/commands/<name>.py`` is one command each, every registered command has its module, and no
    module of the package imports a command module (cli.py registers them by name, with importlib; the
    commands share only ``commands.common``)."""
    edges, _ = _import_graph()
    registered = _registered_commands()
    assert {"identify", "diagnose", "inspect", "excite", "fleet", "export-urdf"} <= set(registered), registered
    modules = {m.rpartition(".")[2] for m in edges if m.startswith("symoro_gen.commands.")} - {"common"}
    assert modules == set(registered.values()), (sorted(modules), registered)
    commands = {f"symoro_gen.commands.{m}" for m in modules}
    found = [f"{a} imports {b} ({', '.join(w)})" for a, bs in edges.items() for b, w in bs.items() if b in commands]
    assert not found, "command modules are leaves:\n" + "\n".join(found)


def test_report_toolkit_is_generic():
    """``symoro_gen.report`` (documents, tables, plots) depends on no stage: neither directly nor through
    another module does it import identification, diagnostics, observations or the workflows."""
    edges, _ = _import_graph()
    stages = ("symoro_gen.identification", "symoro_gen.diagnostics", "symoro_gen.observations", "symoro_gen.workflows")
    report_modules = [m for m in edges if m == "symoro_gen.report" or m.startswith("symoro_gen.report.")]
    assert len(report_modules) >= 3, report_modules
    found = [f"{m} -> ... {via} -> {b}" for m in report_modules for b, via in _reachable(edges, m).items()
             if b.startswith(stages)]
    assert not found, "\n".join(found)


#: calls that parse a data file, by (module alias, function): only the readers (preprocessing/readers) make them
FILE_PARSERS = {("np", "loadtxt"), ("np", "genfromtxt"), ("np", "load"), ("numpy", "load"), ("pd", "read_csv"),
                ("pandas", "read_csv"), ("sio", "loadmat"), ("io", "loadmat"), ("pq", "read_table"),
                ("pq", "ParquetFile"), ("csv", "reader"), ("csv", "DictReader")}
#: the modules outside the readers that parse a file that is not a recording: module -> what it reads
OTHER_FILES_OK = {"identification/reference.py": "a published table of base parameters (--reference CSV)"}


def test_one_reader_for_every_recording():
    """Recordings are read by one front door, ``read_recording`` (``symoro_gen.preprocessing.readers``, one
    module per format): identify, diagnose and inspect read through ``workflows.base`` and the fleet through
    ``fleet.files``, which import it; and no other module parses a data file itself."""
    edges, _ = _import_graph()
    readers = "symoro_gen.preprocessing.readers"
    for user in ("symoro_gen.workflows.identify", "symoro_gen.workflows.diagnose", "symoro_gen.workflows.inspect",
                 "symoro_gen.fleet.files"):
        assert readers in _reachable(edges, user), f"{user} does not read through {readers}"
    assert readers in edges["symoro_gen.workflows.base"] and readers in edges["symoro_gen.fleet.files"]
    found = []
    for _, f in _modules():
        rel = f.relative_to(PKG).as_posix()
        if rel.startswith("preprocessing/readers/") or rel in OTHER_FILES_OK:
            continue
        for node in ast.walk(ast.parse(f.read_text())):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                    and isinstance(node.func.value, ast.Name) and (node.func.value.id, node.func.attr) in FILE_PARSERS):
                found.append(f"{rel}:{node.lineno} {node.func.value.id}.{node.func.attr}")
    assert not found, "data files parsed outside the readers:\n" + "\n".join(found)
    assert all((PKG / rel).is_file() for rel in OTHER_FILES_OK), OTHER_FILES_OK


#: an issue tracker's number in prose ("issue 12", "issue #12", "#12"): features are named instead
ISSUE_NUMBER = re.compile(r"issue *#?[0-9]|#[0-9]{2}\b", re.IGNORECASE)


def test_no_issue_numbers_in_the_package():
    """Docstrings, comments and messages of the package name the feature, not a tracker's issue number."""
    found = [f"{f.relative_to(PKG).as_posix()}:{k}: {line.strip()}" for _, f in _modules()
             for k, line in enumerate(f.read_text().splitlines(), start=1) if ISSUE_NUMBER.search(line)]
    assert not found, "\n".join(found)
    assert ISSUE_NUMBER.search("see issue 10") and ISSUE_NUMBER.search("(#12)") and not ISSUE_NUMBER.search("#1f77b4")


#: the ``# type: ignore`` comments the package keeps, per file: (most allowed, why mypy cannot see it). A new one
#: needs its entry here; the counts only fall (a fixed file may drop below its count).
TYPE_IGNORES_OK: dict[str, tuple[int, str]] = {
    "model.py": (1, "as_model returns an object checked attribute by attribute against the Protocol"),
    "observations/fused.py": (1, "generated models take out= (not in the IdentificationModel Protocol)"),
    "emit/printing.py": (1, "subclass of SymPy's untyped printer"),
    "preprocessing/readers/parquet.py": (1, "pyarrow has no type information"),
    "fleet/files.py": (1, "pyarrow has no type information"),
    "fleet/worker.py": (1, "the WorkerPlugin base falls back to object without the fleet extra"),
    "diagnostics/stats.py": (1, "threadpoolctl has no type information"),
    "diagnostics/unexplained.py": (1, "threadpoolctl has no type information"),
}


def test_type_checking_is_not_switched_off():
    """mypy checks every module: no ``ignore_errors`` in pyproject.toml, and no ``# type: ignore`` beyond the
    ones listed in TYPE_IGNORES_OK with their reason (``warn_unused_ignores`` removes the stale ones)."""
    config = (PKG.parent / "pyproject.toml").read_text()
    assert "[tool.mypy]" in config and not re.search(r"^\s*ignore_errors\s*=", config, re.MULTILINE)
    counts: dict[str, int] = {}
    for _, f in _modules():
        n = len(re.findall(r"#\s*type:\s*ignore", f.read_text()))
        if n:
            counts[f.relative_to(PKG).as_posix()] = n
    over = {rel: n for rel, n in counts.items() if n > TYPE_IGNORES_OK.get(rel, (0, ""))[0]}
    assert not over, f"new `# type: ignore` comments (fix the type, or list the file with its reason): {over}"
