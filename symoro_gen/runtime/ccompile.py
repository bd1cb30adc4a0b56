"""Compile and load the C file of a generated package (``regressor_<robot>.c``).

The shared library is named by the sha256 of the C source, the compiler flags and the CPU
(``-march=native`` code only runs where it was built), and placed in ``_build/`` beside the
package when that folder is writable, else in the user cache
(``$XDG_CACHE_HOME/symoro_gen/build``, default ``~/.cache/symoro_gen/build``).

Compilation happens in a private temporary folder; the finished library is renamed into place,
so a failure, a timeout or an interrupt never leaves a partial or 0-byte library, nor the folders the
build created (an empty ``_build/``). On timeout the compiler (its whole process group) is killed; the
error then says how to retry with more time, and the package evaluates with its NumPy kernels meanwhile. Large sources (above :data:`LARGE_SOURCE` bytes)
are compiled at ``-O1`` so that they finish (a 4 MB source at ``-O3`` took more than 300 s).
"""
from __future__ import annotations

import ctypes
import hashlib
import os
import platform
import shutil
import signal
import subprocess
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..atomic import ordinary_mode
from ..errors import ModelError

#: sources larger than this (bytes) are compiled at -O1 instead of -O3
LARGE_SOURCE = 1_500_000
#: default compile timeout in seconds (``$SYMORO_CC_TIMEOUT`` overrides)
TIMEOUT_S = 900.0
_COMMON_FLAGS = ("-march=native", "-fPIC", "-shared", "-fno-math-errno")


class CBuildError(ModelError):
    """The C kernels could not be compiled or loaded (no compiler, compile error, timeout)."""


@dataclass(frozen=True)
class BuildResult:
    """Where the library is, and whether this call compiled it."""

    path: Path
    compiled: bool


def compiler() -> str | None:
    """The C compiler to use: ``$CC``, else cc, gcc or clang on the PATH; None when there is none."""
    for c in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if c and shutil.which(c):
            return shutil.which(c)
    return None


def compile_flags(source_size: int, opt: str | None = None) -> list[str]:
    """-O3, or -O1 for sources above :data:`LARGE_SOURCE` bytes (``opt``, e.g. ``"-O0"``, when given),
    plus the common flags."""
    if opt is None:
        opt = "-O1" if source_size > LARGE_SOURCE else "-O3"
    return [opt, *_COMMON_FLAGS]


def _cpu_tag() -> str:
    """Identity of this CPU model and instruction set (``-march=native`` libraries are not portable)."""
    info = platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
            keep = [ln for ln in fh.read().splitlines() if ln.startswith(("model name", "flags", "Features"))]
        info += "\n".join(dict.fromkeys(keep))
    except OSError:
        info += platform.processor()
    return info


def library_name(c_path: Path, source: bytes, opt: str | None = None) -> str:
    """File name of the library of one C source: ``<stem>_<sha256 of source, flags, CPU>.so``."""
    flags = " ".join(compile_flags(len(source), opt))
    tag = hashlib.sha256(source + b"\0" + flags.encode() + b"\0" + _cpu_tag().encode()).hexdigest()[:16]
    return f"{c_path.stem}_{tag}.so"


def user_cache() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "symoro_gen" / "build"


def build_dirs(c_path: Path) -> list[Path]:
    """Candidate library folders, in order: ``_build/`` beside the package, the user cache."""
    return [c_path.parent / "_build", user_cache()]


def find_library(c_path: Path, opt: str | None = None) -> Path | None:
    """An already-built library of this exact source (and optimisation level ``opt``), or None."""
    name = library_name(c_path, c_path.read_bytes(), opt)
    for d in build_dirs(c_path):
        if (d / name).is_file() and (d / name).stat().st_size > 0:
            return d / name
    return None


def _writable_dir(d: Path) -> bool:
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError:
        return False
    return os.access(d, os.W_OK | os.X_OK)


def _run_compiler(cmd: list[str], timeout: float) -> None:
    """Run the compiler; on timeout or interrupt kill its process group. Raises CBuildError."""
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    try:
        _, err = proc.communicate(timeout=timeout)
    except BaseException as exc:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except (OSError, AttributeError):
            proc.kill()
        proc.communicate()
        if isinstance(exc, subprocess.TimeoutExpired):
            raise CBuildError(f"the C compiler did not finish within {timeout:g} s (killed)") from None
        raise
    if proc.returncode != 0:
        lines = [ln for ln in err.decode(errors="replace").splitlines() if ln.strip()]
        first = next((ln for ln in lines if "error" in ln), lines[0] if lines else "")
        raise CBuildError(f"the C compiler failed (exit {proc.returncode}): {first.strip()}")


def build_library(c_path: str | os.PathLike[str], *, timeout: float | None = None, force: bool = False,
                  opt: str | None = None) -> BuildResult:
    """Find, or compile, the shared library of ``c_path``.

    Parameters
    ----------
    c_path : path
        The package's ``regressor_<robot>.c``.
    timeout : float, optional
        Seconds before the compiler is killed (default ``$SYMORO_CC_TIMEOUT`` or :data:`TIMEOUT_S`).
    force : bool
        Compile even when a library of this source exists.
    opt : str, optional
        Optimisation flag instead of the size rule of :func:`compile_flags` (the geometry derivative's
        long straight-line function takes minutes at ``-O1`` with GCC: it is compiled at ``-O0``).

    Raises
    ------
    CBuildError
        No compiler, compile error, timeout, or no writable folder.
    """
    c_path = Path(c_path).resolve()
    if not force:
        found = find_library(c_path, opt)
        if found is not None:
            return BuildResult(found, False)
    cc = compiler()
    if cc is None:
        raise CBuildError("no C compiler found (set $CC, or install cc/gcc/clang)")
    source = c_path.read_bytes()
    name = library_name(c_path, source, opt)
    if timeout is None:
        timeout = float(os.environ.get("SYMORO_CC_TIMEOUT", TIMEOUT_S))
    for d in build_dirs(c_path):
        created = _missing_dirs(d)
        if not _writable_dir(d):
            _remove_empty(created)
            continue
        tmp = Path(tempfile.mkdtemp(prefix=".compiling-", dir=d))
        try:
            lib = tmp / name
            _run_compiler([cc, *compile_flags(len(source), opt), "-o", str(lib), str(c_path), "-lm"], timeout)
            os.chmod(lib, ordinary_mode(is_dir=True))  # rwx like an executable
            os.replace(lib, d / name)
        except CBuildError as exc:
            shutil.rmtree(tmp, ignore_errors=True)
            _remove_empty(created)
            err = CBuildError(f"{c_path}: {exc}; nothing was left behind")
            err.hint = (f"retry with more time: `symoro-gen build {c_path.parent} --timeout {2 * timeout:g}` (or "
                        "$SYMORO_CC_TIMEOUT)" if "did not finish" in str(exc) else
                        f"`symoro-gen build {c_path.parent}` retries and shows the compiler's error")
            raise err from None
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            _remove_empty(created)
            raise
        shutil.rmtree(tmp, ignore_errors=True)
        return BuildResult(d / name, True)
    raise CBuildError(f"no writable folder for the compiled library (tried {', '.join(map(str, build_dirs(c_path)))})")


def _missing_dirs(d: Path) -> list[Path]:
    """``d`` and its parents that do not exist yet, deepest first (those a build would create)."""
    out = []
    while not d.exists() and d != d.parent:
        out.append(d)
        d = d.parent
    return out


def _remove_empty(dirs: Sequence[Path]) -> None:
    """Remove the folders a failed build created (deepest first), each only when it is empty."""
    for d in dirs:
        try:
            d.rmdir()
        except OSError:
            return


def load_functions(lib_path: Path, names: Sequence[str]) -> dict[str, Any]:
    """ctypes functions ``{name: fn(N, q, dq, ddq, out)}`` of a built library (CBuildError when not loadable)."""
    try:
        lib = ctypes.CDLL(str(lib_path))
        ptr = np.ctypeslib.ndpointer(dtype=np.float64, flags="C_CONTIGUOUS")
        out = {}
        for name in names:
            fn = getattr(lib, name)
            fn.restype = None
            fn.argtypes = [ctypes.c_long, ptr, ptr, ptr, ptr]
            out[name] = fn
    except (OSError, AttributeError) as exc:
        raise CBuildError(f"cannot load {lib_path}: {exc}") from None
    return out
