"""Atomic file writing, the one place: a temporary sibling renamed over the target, so a failure
never leaves a half-written output. Files get ordinary permissions (``0666 & ~umask``), not
mkstemp's private ones.

Used for robot files, JSON results, reports (single files and a report's image folder) and
diagnosis figures. The generated packages are written by ``emit.package.write_package_atomic``
(the same folder swap, kept beside the emitter).
"""
from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Mapping
from pathlib import Path

__all__ = ["ordinary_mode", "replace_folder_atomic", "write_bytes_atomic", "write_text_atomic"]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def ordinary_mode(is_dir: bool = False) -> int:
    """``0777`` (folders) or ``0666`` (files) minus the process umask."""
    return (0o777 if is_dir else 0o666) & ~_umask()


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes, *, overwrite: bool = True) -> None:
    """Write ``data`` to ``path`` through a temporary sibling and a rename.

    Parameters
    ----------
    path : str or PathLike
        Destination; its folder is created when missing.
    data : bytes
    overwrite : bool
        When false an existing ``path`` is never replaced, even one that appears while writing
        (the temporary file is hard-linked to ``path``): ``FileExistsError``.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, ordinary_mode())
        if overwrite:
            os.replace(tmp, path)
        else:
            try:
                os.link(tmp, path)  # fails if path exists: never clobbers
            except FileExistsError:
                raise
            except OSError:  # file system without hard links
                if path.exists():
                    raise FileExistsError(str(path)) from None
                os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def write_text_atomic(path: str | os.PathLike[str], text: str, *, overwrite: bool = True) -> None:
    """UTF-8 text, ``\\n`` line ends, written atomically (see :func:`write_bytes_atomic`)."""
    write_bytes_atomic(path, text.encode("utf-8"), overwrite=overwrite)


def replace_folder_atomic(folder: str | os.PathLike[str], files: Mapping[str, bytes | str]) -> None:
    """Make ``folder`` hold exactly ``files`` (name -> content), swapped in with one rename.

    The files are written into a temporary sibling folder, the old folder (if any) is moved
    aside, the new one renamed into place, and the old one removed; on failure the old folder
    is restored. Text is written as UTF-8.

    Raises
    ------
    NotADirectoryError
        ``folder`` exists and is not a folder.
    """
    folder = Path(folder)
    folder.parent.mkdir(parents=True, exist_ok=True)
    if folder.exists() and not folder.is_dir():
        raise NotADirectoryError(str(folder))
    tmp = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", suffix=".tmp", dir=folder.parent))
    old = None
    try:
        os.chmod(tmp, ordinary_mode(is_dir=True))  # mkdtemp makes it private
        for name, data in files.items():
            (tmp / name).write_bytes(data.encode("utf-8") if isinstance(data, str) else data)
        if folder.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", suffix=".old", dir=folder.parent))
            old.rmdir()
            os.replace(folder, old)
        os.replace(tmp, folder)
    except BaseException:
        if tmp.exists():
            shutil.rmtree(tmp)
        if old is not None and old.exists() and not folder.exists():
            os.replace(old, folder)
        raise
    if old is not None and old.exists():
        shutil.rmtree(old)
