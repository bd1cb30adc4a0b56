"""Batch evaluation of NumPy kernels ``kernel(q, dq, ddq, out)`` (emitted by
:mod:`symoro_gen.emit.backends.numpy`) in cache-sized chunks of samples."""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: samples per kernel call: the (n, ncols, chunk) buffer stays in cache
CHUNK = 2048


def evaluate_kernel(kernel: Callable[..., Any], n_rows: int, n_cols: int, q: NDArray[np.float64], dq: NDArray[np.float64],
                    ddq: NDArray[np.float64], res: NDArray[np.float64], chunk: int = CHUNK) -> NDArray[np.float64]:
    """Fill ``res`` (N, n_rows, n_cols) from (N, n) inputs; the kernel works on (n, M) transposes."""
    N = q.shape[0]
    m = min(chunk, max(N, 1))
    buf = np.zeros((n_rows, n_cols, m))
    for s in range(0, N, chunk):
        e = min(N, s + chunk)
        b = buf if e - s == m else np.zeros((n_rows, n_cols, e - s))
        b.fill(0.0)
        kernel(np.ascontiguousarray(q[s:e].T), np.ascontiguousarray(dq[s:e].T), np.ascontiguousarray(ddq[s:e].T), b)
        res[s:e] = b.transpose(2, 0, 1)
    return res


def evaluate(kernel: Callable[..., Any], n_rows: int, n_cols: int, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike, *, chunk: int = CHUNK) -> NDArray[np.float64]:
    """Evaluate a kernel over samples; returns (N, n_rows, n_cols), (n_rows, n_cols) for 1-D inputs."""
    q, dq, ddq = (np.asarray(x, dtype=float) for x in (q, dq, ddq))
    one = q.ndim == 1
    q, dq, ddq = (np.atleast_2d(x) for x in (q, dq, ddq))
    if not (q.shape == dq.shape == ddq.shape) or q.ndim != 2:
        raise ValueError(f"q, dq, ddq must have the same shape (N, n), got {q.shape}, {dq.shape}, {ddq.shape}")
    res = evaluate_kernel(kernel, n_rows, n_cols, q, dq, ddq, np.empty((q.shape[0], n_rows, n_cols)), chunk)
    return res[0] if one else res
