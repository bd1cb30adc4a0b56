"""Atomic file writing: a temporary sibling renamed over the target, so a failure never leaves a
half-written output. Files get ordinary permissions (``0666 & ~umask``), not mkstemp's private ones."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def ordinary_mode(is_dir: bool = False) -> int:
    return (0o777 if is_dir else 0o666) & ~_umask()


def write_bytes_atomic(path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary sibling and a rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.chmod(tmp, ordinary_mode())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_text_atomic(path, text: str) -> None:
    """UTF-8 text, ``\\n`` line ends, written atomically."""
    write_bytes_atomic(path, text.encode("utf-8"))
