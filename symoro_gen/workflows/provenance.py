"""The provenance block and schema version every workflow's JSON carries (docs/json-output.md).

Kept apart from :mod:`symoro_gen.workflows.base` (which loads the data readers) so that the light workflows (the
exports: no SciPy, no readers) stamp their JSON the same way: :data:`SCHEMA_VERSION`, :func:`provenance_block`
(package version and commit, the options, each input file with its sha256, the seeds).
"""
from __future__ import annotations

import functools
import hashlib
import os
import subprocess
from collections.abc import Iterable, Mapping
from typing import Any

from .. import __version__
from ..paths import REPO_ROOT

__all__ = ["SCHEMA_VERSION", "file_sha256", "package_commit", "provenance_block"]

#: version of the JSON written by the commands and returned by ``Results.to_dict()`` (docs/json-output.md):
#: 2 added ``schema_version`` and ``provenance``
SCHEMA_VERSION = 2


def file_sha256(path: str | os.PathLike[str]) -> str | None:
    """sha256 of a file's bytes (None when it is not a readable file)."""
    h = hashlib.sha256()
    try:
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
    except OSError:
        return None
    return h.hexdigest()


@functools.lru_cache(maxsize=1)
def package_commit() -> str | None:
    """The git commit of the checkout the package runs from (None outside a git checkout)."""
    if not (REPO_ROOT / ".git").exists():
        return None
    try:
        out = subprocess.run(["git", "-C", str(REPO_ROOT), "rev-parse", "HEAD"], capture_output=True, text=True,
                             timeout=5, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() or None if out.returncode == 0 else None


def provenance_block(options: Mapping[str, Any], inputs: Iterable = (),
                     seeds: Mapping[str, Any] | None = None) -> dict:
    """The JSON's provenance block: package version and commit, the options (JSON-ready), each input file with
    its sha256 (in-memory data as its source name, hash null), the seeds used."""
    files = []
    for x in inputs:
        if isinstance(x, (str, os.PathLike)):
            files.append({"path": os.fspath(x), "sha256": file_sha256(x)})
        else:
            files.append({"path": str(getattr(x, "source", "<in memory>")), "sha256": None})
    return {"package": {"name": "symoro_gen", "version": __version__, "commit": package_commit()},
            "options": dict(options), "inputs": files, "seeds": dict(seeds or {})}
