"""Checking the joint-state inputs of a regressor call."""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray


def joint_states(robot: str, n: int, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike
                 ) -> tuple[tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]], bool]:
    """``((q, dq, ddq) as (N, n) float arrays, one_sample)``; ``(n,)`` inputs count as one sample.

    Raises
    ------
    ValueError
        Naming the robot, the argument and the shape expected.
    """
    arrs = []
    for name, x in (("q", q), ("dq", dq), ("ddq", ddq)):
        a = np.asarray(x, dtype=float)
        if a.ndim == 1 and a.shape[0] == n:
            a = a[None, :]
        elif not (a.ndim == 2 and a.shape[1] == n):
            raise ValueError(f"{robot}: {name} must have shape (N, {n}) or ({n},), got {a.shape}")
        arrs.append(a)
    if not arrs[0].shape[0] == arrs[1].shape[0] == arrs[2].shape[0]:
        raise ValueError(f"{robot}: q, dq, ddq have different sample counts {[a.shape[0] for a in arrs]}")
    return (arrs[0], arrs[1], arrs[2]), np.ndim(q) == 1


def output_array(robot: str, shape: tuple[int, int, int], out: NDArray[np.float64] | None) -> NDArray[np.float64]:
    """``out`` checked (C-contiguous float64 of ``shape``), or a new array."""
    if out is None:
        return np.empty(shape)
    if out.shape != shape or out.dtype != np.float64 or not out.flags.c_contiguous:
        raise ValueError(f"{robot}: out must be a C-contiguous float64 array of shape {shape}")
    return out
