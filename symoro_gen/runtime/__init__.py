"""Run-time support of generated packages (``generated/<robot>/``).

A generated package holds only its data (names, relations, constants) and its kernels (NumPy
source ``_kernels.py``, CasADi construction ``_casadi.py``, one C file ``regressor_<robot>.c``);
its ``__init__.py`` binds them to :class:`GeneratedModel`, which does input checking, batch
evaluation, loading (or compiling, on first need) the C kernels, and the CasADi construction.

Importing a generated package compiles nothing: C is compiled by ``symoro-gen build ROBOT`` or
lazily by the first evaluation, and falls back to NumPy with one warning when it cannot be.
"""
from .ccompile import BuildResult, CBuildError, build_library
from .model import GeneratedModel

__all__ = ["BuildResult", "CBuildError", "GeneratedModel", "build_library"]
