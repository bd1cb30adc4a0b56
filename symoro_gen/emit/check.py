"""Is the committed ``generated/`` what the generator produces? (``make check-generated``)

Every file of every package is compared byte for byte, except the ``tool_versions`` entry of
``manifest.json`` (recorded for information: a fresh install with other versions of sympy, NumPy
or CasADi must still pass when the generated code is the same). Run as
``python -m symoro_gen.emit.check [GENERATED_DIR]``; exit status 1 lists the differences.
"""
from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

from ..description import load_robot, robots_dir
from ..loader import generated_dir
from .package import emit_robot

#: never compared: build products and caches
IGNORED = frozenset({"__pycache__", "_build"})


def _manifest_without_versions(text: str) -> object:
    man = json.loads(text)
    if isinstance(man, dict):
        man.pop("tool_versions", None)
    return man


def compare_packages(committed: Path, fresh: Path) -> list[str]:
    """Names of the files that differ between two package folders (missing or extra ones included),
    ``manifest.json`` compared without its ``tool_versions``."""
    a = {p.name for p in committed.iterdir() if p.name not in IGNORED} if committed.is_dir() else set()
    b = {p.name for p in fresh.iterdir() if p.name not in IGNORED}
    diffs = sorted(f"{n} (only in {committed if n in a else fresh})" for n in a ^ b)
    for n in sorted(a & b):
        x, y = (committed / n).read_bytes(), (fresh / n).read_bytes()
        if n == "manifest.json":
            same = _manifest_without_versions(x.decode()) == _manifest_without_versions(y.decode())
        else:
            same = x == y
        if not same:
            diffs.append(n)
    return diffs


def check_generated(folder: Path | None = None, robots: list[str] | None = None) -> dict[str, list[str]]:
    """Regenerate every robot of ``robots/`` into a temporary folder and compare with ``folder``
    (default: the repository's ``generated/``). Returns ``{robot: differing files}`` (empty lists when equal)."""
    folder = folder or generated_dir()
    names = robots if robots is not None else sorted(p.stem for p in robots_dir().glob("*.toml"))
    out: dict[str, list[str]] = {}
    with tempfile.TemporaryDirectory(prefix="symoro_check_") as td:
        for name in names:
            emit_robot(load_robot(name), Path(td), source_base=folder.parent)  # robot_file_path as in folder
            out[name] = compare_packages(folder / name, Path(td) / name)
    return out


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    res = check_generated(Path(argv[0]) if argv else None)
    bad = {k: v for k, v in res.items() if v}
    for k, v in bad.items():
        print(f"{k}: differs from the generator: {', '.join(v)}")
    if bad:
        print("generated/ differs from the generator: run `make robots` and commit")
        return 1
    print(f"generated/ matches the generator ({', '.join(res)}; tool versions not compared)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
