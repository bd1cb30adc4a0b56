"""Doctests of the small value types, collected by every ordinary ``pytest`` run.

Only the modules listed here are collected as doctests (``--doctest-modules`` over the whole
package would import heavy optional modules, matplotlib, casadi, at collection); they are also in
``testpaths`` (pyproject.toml) so that a bare ``pytest`` finds them.
``python -m pytest --doctest-modules symoro_gen/params.py ...`` runs the same examples.
"""
from __future__ import annotations

from pathlib import Path

from _pytest.doctest import DoctestModule

ROOT = Path(__file__).resolve().parent
DOCTEST_MODULES = frozenset(ROOT / p for p in (
    "symoro_gen/params.py",
    "symoro_gen/description/mdh.py",
    "symoro_gen/description/inertia.py",
    "symoro_gen/description/model.py",
))


def pytest_collect_file(file_path, parent):
    if file_path.resolve() in DOCTEST_MODULES and not parent.config.option.doctestmodules:
        return DoctestModule.from_parent(parent, path=file_path)
    return None
