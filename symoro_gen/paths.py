"""The repository's folders of robot files and generated models (``$SYMORO_ROBOTS`` and
``$SYMORO_GENERATED`` override them).

A module of its own with no dependency on the rest of the package, so that the robot-file parser and the
loader (which imports the parser) both use it without importing each other.
"""
from __future__ import annotations

import os
from pathlib import Path

__all__ = ["REPO_ROOT", "generated_dir", "robots_dir"]

#: the repository holding this package (``generated/`` and ``robots/`` live there)
REPO_ROOT = Path(__file__).resolve().parents[1]


def generated_dir() -> Path:
    """Default folder of generated models (``$SYMORO_GENERATED`` overrides)."""
    env = os.environ.get("SYMORO_GENERATED")
    return Path(env) if env else REPO_ROOT / "generated"


def robots_dir() -> Path:
    """Folder holding the shipped robot files (``$SYMORO_ROBOTS`` overrides)."""
    env = os.environ.get("SYMORO_ROBOTS")
    return Path(env) if env else REPO_ROOT / "robots"
