"""Compile and load the C kernels of this generated package (generated helper).

The shared library is built once with the system C compiler (``$CC`` or cc/gcc/clang) into
``_build/`` beside this file (or a user cache folder when that is read-only), named by the
hash of the C source, and loaded with ctypes. Without a compiler, or with
``SYMORO_BACKEND=numpy``, callers fall back to the NumPy kernels.
"""
import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

_HERE = Path(__file__).resolve().parent
#: -march=native: the library is built on, and cached for, the machine that runs it
_FLAGS = ["-O3", "-march=native", "-fPIC", "-shared", "-fno-math-errno"]


def _compiler():
    for c in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if c and shutil.which(c):
            return shutil.which(c)
    return None


def _build_dirs():
    yield _HERE / "_build"
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    yield Path(base) / "symoro_gen"
    yield Path(tempfile.gettempdir()) / "symoro_gen"


def load(functions):
    """ctypes functions ``{name: fn}`` for the batch kernels, or None when C is unavailable."""
    if os.environ.get("SYMORO_BACKEND", "").lower() == "numpy":
        return None
    src = (_HERE / "_kernels.c").read_bytes()
    import platform

    tag = hashlib.sha256(src + " ".join(_FLAGS).encode() + platform.node().encode()).hexdigest()[:16]
    lib_path = None
    for d in _build_dirs():
        cand = d / f"kernels_{tag}.so"
        if cand.exists():
            lib_path = cand
            break
    if lib_path is None:
        cc = _compiler()
        if cc is None:
            return None
        for d in _build_dirs():
            try:
                d.mkdir(parents=True, exist_ok=True)
                fd, tmp = tempfile.mkstemp(suffix=".so", dir=d)
                os.close(fd)
                r = subprocess.run(
                    [cc, *_FLAGS, "-o", tmp, str(_HERE / "_kernels.c"), "-lm"],
                    capture_output=True,
                    timeout=300,
                )
                if r.returncode != 0:
                    os.unlink(tmp)
                    return None
                lib_path = d / f"kernels_{tag}.so"
                os.replace(tmp, lib_path)
                break
            except OSError:
                continue
        if lib_path is None:
            return None
    try:
        lib = ctypes.CDLL(str(lib_path))
    except OSError:
        return None
    out = {}
    ptr = np.ctypeslib.ndpointer(dtype=np.float64, flags="C_CONTIGUOUS")
    for name in functions:
        fn = getattr(lib, name)
        fn.restype = None
        fn.argtypes = [ctypes.c_long, ptr, ptr, ptr, ptr]
        out[name] = fn
    return out
