"""docs/architecture.md stays true: every file and module it names exists, and it covers every package."""
import re

from .runner import DOCS, ROOT

PAGE = DOCS / "architecture.md"
PATH = re.compile(r"`((?:symoro_gen|tests|docs|generated|robots)/[^`\s]*)`")
DOTTED = re.compile(r"(?<![/\w.])(?:observations|identification|diagnostics|preprocessing|description|dynamics|baseparams|emit|"
                    r"runtime|report|simulate)\.[a-z_]+(?:\.\{?[a-z_,]+\}?)?")


def _exists(rel: str) -> bool:
    if "<" in rel:  # a pattern such as generated/<robot>/
        return (ROOT / rel.split("<")[0]).is_dir()
    if "*" in rel:  # a glob such as robots/*.toml
        return any(ROOT.glob(rel))
    return (ROOT / rel.rstrip("/")).exists()


def test_every_named_path_exists():
    text = PAGE.read_text()
    paths = PATH.findall(text)
    assert len(paths) > 60, "the map names the modules by path"
    missing = sorted({p for p in paths if not _exists(p)})
    assert not missing, f"docs/architecture.md names files that do not exist: {missing}"


def test_every_dotted_module_in_the_diagrams_exists():
    """The flow diagrams name modules as ``package.module`` (``emit.backends.{numpy,c,casadi}``)."""
    text = PAGE.read_text()
    missing = []
    for name in set(DOTTED.findall(text)):
        if name.endswith(".py"):
            continue
        head, _, tail = name.partition("{")
        stems = [head + t for t in tail.rstrip("}").split(",")] if tail else [head]
        for stem in stems:
            base = ROOT / "symoro_gen" / stem.rstrip(".").replace(".", "/")
            if not (base.with_suffix(".py").is_file() or (base / "__init__.py").is_file()):
                missing.append(stem)
    assert not missing, f"docs/architecture.md names modules that do not exist: {sorted(missing)}"


def test_every_module_of_the_package_is_on_the_map():
    """A new module must be placed on the map (the map is the layout, not a sample of it)."""
    text = PAGE.read_text()
    named = set(PATH.findall(text))
    left = []
    for f in sorted((ROOT / "symoro_gen").rglob("*.py")):
        rel = f.relative_to(ROOT).as_posix()
        if f.name in ("__init__.py", "__main__.py") or rel in named:
            continue
        left.append(rel)
    # re-export shims of moved code are not on the map
    shims = {"symoro_gen/identification/assemble.py", "symoro_gen/identification/observation.py",
             "symoro_gen/emit/numpy_backend.py"}
    assert not set(left) - shims, f"modules missing from docs/architecture.md: {sorted(set(left) - shims)}"
