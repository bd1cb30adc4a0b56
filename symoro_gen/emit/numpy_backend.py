"""Transitional names for ``baseparams/regroup.py`` (until it uses the numeric graph evaluator of
``symoro_gen.dynamics``): the NumPy backend lives in :mod:`symoro_gen.emit.backends.numpy`."""
from ..runtime.batch import evaluate
from .backends.numpy import kernel_source, load_kernel

__all__ = ["evaluate", "kernel_source", "load_kernel"]
