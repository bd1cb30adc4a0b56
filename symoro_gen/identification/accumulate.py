"""Streaming accumulation of an observation system as per-joint QR factors (TSQR).

For each joint j the accumulator keeps the upper-triangular factor ``R_j`` of ``[W_j  Y_j]``
(``W_j``, ``Y_j``: all rows of joint j seen so far), the number of rows and ``Y_j'Y_j``. A new
chunk is absorbed by stacking ``R_j`` on the chunk's rows of joint j and re-factoring, so memory
is ``n_joints * (c+1)^2`` whatever the number of samples.

Everything the estimators need is exact on these factors, because ``[W_j Y_j] = Q_j R_j`` with
``Q_j`` orthonormal:

* OLS: ``[W Y] = blockdiag(Q_j) [R_1; ...; R_n]``, so the least-squares solution, the residual norm,
  ``W'W`` and the singular values of ``W`` are those of the stacked factors;
* WLS (eq. 22): the per-joint OLS of joint j only needs ``R_j``, and the weighted system is the
  stack of ``R_j / sigma_j``;
* TLS: the singular values and right singular vectors of ``W_tot = [W  -Y]`` are those of the
  stacked factors with the last column negated (LWR4 paper eq. 12-16);
* per-joint error norms: ``||Y_j - W_j x|| = ||R_j [x; -1]||``.

Column subsets (essential parameters) are handled by taking the matching columns of the factors.
"""
from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import IdentificationError
from .observation import ObservationSystem

#: rows per Householder QR when absorbing a chunk (small blocks stay in cache: ~1.6x faster than one QR)
QR_BLOCK_ROWS = 512


def _absorb(R: np.ndarray, M: np.ndarray, block_rows: int = QR_BLOCK_ROWS) -> np.ndarray:
    """Factor R' (k, k) with R'R' = R'R + M'M, computing the QR only on the non-zero columns of M
    (the rows of joint j involve the parameters of links j..n only) and in blocks of rows."""
    k = R.shape[1]
    nz = np.flatnonzero(np.any(M != 0.0, axis=0))
    if nz.size == 0:
        return R
    Mz = M[:, nz]
    Rz = np.zeros((0, nz.size))
    for i in range(0, Mz.shape[0], block_rows):
        Rz = np.asarray(np.linalg.qr(np.vstack([Rz, Mz[i:i + block_rows]]), mode="r"))
    S = np.zeros((Rz.shape[0], k))
    S[:, nz] = Rz
    return _triangular_factor(np.vstack([R, S]), k)


def _triangular_factor(M: np.ndarray, ncols: int) -> np.ndarray:
    """Upper-triangular R (ncols, ncols) with R'R = M'M (zero-padded when M has fewer rows)."""
    if M.shape[0] == 0:
        return np.zeros((ncols, ncols))
    R = np.asarray(np.linalg.qr(M, mode="r"))
    if R.shape[0] < ncols:
        R = np.vstack([R, np.zeros((ncols - R.shape[0], ncols))])
    return R


def check_finite(system: ObservationSystem, what: str = "observation system") -> None:
    """Raise :class:`IdentificationError` naming the column and rows holding NaN or inf."""
    if not np.isfinite(system.Y).all():
        bad = np.flatnonzero(~np.isfinite(system.Y))
        raise IdentificationError(
            f"{what}: Y has {bad.size} non-finite value(s), rows {bad[0]}-{bad[-1]} "
            f"(joint {system.joint[bad[0]] + 1})")
    finite = np.isfinite(system.W)
    if not finite.all():
        col = int(np.flatnonzero(~finite.all(axis=0))[0])
        bad = np.flatnonzero(~finite[:, col])
        raise IdentificationError(
            f"{what}: column {system.names[col]!r} of W has {bad.size} non-finite value(s), "
            f"rows {bad[0]}-{bad[-1]} (joint {system.joint[bad[0]] + 1})")
    if system.weights is not None and not np.isfinite(system.weights).all():
        bad = np.flatnonzero(~np.isfinite(system.weights))
        raise IdentificationError(f"{what}: row weights are non-finite at rows {bad[0]}-{bad[-1]}")


@dataclass(frozen=True, eq=False)
class Accumulator:
    """Per-joint TSQR factors of ``[W_j  Y_j]`` (an immutable value; :meth:`add` returns a new one).

    Attributes
    ----------
    names : tuple of str, length c
        Column labels; every chunk must carry the same labels in the same order.
    R : tuple of ndarray, each (c+1, c+1)
        Upper-triangular factor of ``[W_j Y_j]`` for joint j (0-based).
    rows : tuple of int
        Number of rows absorbed per joint.
    yy : tuple of float
        ``Y_j' Y_j`` per joint.
    weighted : bool
        When True, the rows of each chunk are multiplied by its ``weights`` before absorption.
    """

    names: tuple[str, ...]
    R: tuple[np.ndarray, ...] = ()
    rows: tuple[int, ...] = ()
    yy: tuple[float, ...] = ()
    weighted: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "names", tuple(self.names))
        c1 = len(self.names) + 1
        Rs = []
        for R in self.R:
            R = np.array(R, float)
            if R.shape != (c1, c1):
                raise IdentificationError(f"Accumulator: factor of shape {R.shape}, expected {(c1, c1)}")
            R.setflags(write=False)
            Rs.append(R)
        object.__setattr__(self, "R", tuple(Rs))
        object.__setattr__(self, "rows", tuple(int(r) for r in self.rows))
        object.__setattr__(self, "yy", tuple(float(v) for v in self.yy))
        if not (len(self.R) == len(self.rows) == len(self.yy)):
            raise IdentificationError("Accumulator: R, rows and yy must have one entry per joint")

    @classmethod
    def empty(cls, names: Sequence[str], n_joints: int = 0, weighted: bool = False) -> Accumulator:
        """An accumulator with no rows for columns ``names`` (and ``n_joints`` joints)."""
        c1 = len(names) + 1
        return cls(tuple(names), tuple(np.zeros((c1, c1)) for _ in range(n_joints)),
                   (0,) * n_joints, (0.0,) * n_joints, weighted)

    @property
    def n_joints(self) -> int:
        return len(self.R)

    @property
    def n_rows(self) -> int:
        return int(sum(self.rows))

    @property
    def n_params(self) -> int:
        return len(self.names)

    def add(self, chunk: ObservationSystem) -> Accumulator:
        """Absorb the rows of ``chunk`` (an :class:`ObservationSystem` with the same column names).

        Returns
        -------
        Accumulator
            A new accumulator; ``self`` is unchanged.
        """
        if not isinstance(chunk, ObservationSystem):
            raise IdentificationError(f"Accumulator.add expects an ObservationSystem, got {type(chunk).__name__}")
        if chunk.names != self.names:
            diff = [n for n in chunk.names if n not in self.names] + [n for n in self.names if n not in chunk.names]
            raise IdentificationError(
                "chunk columns differ from the accumulator's"
                + (f" (not in both: {diff})" if diff else " (same names, different order)"))
        if chunk.weights is not None and not self.weighted:
            raise IdentificationError(
                "chunk carries row weights but the accumulator is unweighted; "
                "use Accumulator.empty(names, weighted=True) to apply them")
        check_finite(chunk, "chunk")
        c1 = len(self.names) + 1
        nj = max(self.n_joints, chunk.n_joints)
        R = list(self.R) + [np.zeros((c1, c1))] * (nj - self.n_joints)
        rows = list(self.rows) + [0] * (nj - self.n_joints)
        yy = list(self.yy) + [0.0] * (nj - self.n_joints)
        M = np.column_stack([chunk.W, chunk.Y])
        if self.weighted and chunk.weights is not None:
            M = M * np.asarray(chunk.weights, float)[:, None]
        order = np.argsort(chunk.joint, kind="stable")
        joints_sorted = chunk.joint[order]
        bounds = np.searchsorted(joints_sorted, np.arange(nj + 1))
        for j in range(nj):
            sel = order[bounds[j]:bounds[j + 1]]
            if sel.size == 0:
                continue
            Mj = M[sel]
            R[j] = _absorb(R[j], Mj)
            rows[j] += int(sel.size)
            yy[j] += float(Mj[:, -1] @ Mj[:, -1])
        return Accumulator(self.names, tuple(R), tuple(rows), tuple(yy), self.weighted)

    def column_sq_norms(self) -> np.ndarray:
        """Squared norm of every column of ``W`` over all joints, shape (c,): column ``i`` of ``W_j`` has the
        norm of column ``i`` of ``R_j`` (``W_j = Q_j R_j``, ``Q_j`` orthonormal)."""
        out = np.zeros(self.n_params)
        for R in self.R:
            out += np.einsum("ij,ij->j", R[:, :-1], R[:, :-1])
        return out

    def without(self, names: Sequence[str]) -> Accumulator:
        """The factors of ``[W  Y]`` without the columns ``names`` (those it lacks are ignored; the factors
        are re-triangularised)."""
        gone = set(names)
        keep = [i for i, nm in enumerate(self.names) if nm not in gone]
        if len(keep) == self.n_params:
            return self
        cols = keep + [self.n_params]
        return Accumulator(tuple(self.names[i] for i in keep),
                           tuple(_triangular_factor(R[:, cols], len(cols)) for R in self.R),
                           self.rows, self.yy, self.weighted)

    def factor(self, j: int, columns: Sequence[int] | None = None) -> np.ndarray:
        """Square-root data of ``[W_j[:, columns]  Y_j]``: a matrix M with the same Gram matrix.

        Returns
        -------
        ndarray, shape (c+1, len(columns)+1)
        """
        R = self.R[j]
        if columns is None:
            return R
        return R[:, list(columns) + [R.shape[1] - 1]]


def accumulate(chunks: Iterable[ObservationSystem], names: Sequence[str] | None = None,
               weighted: bool = False) -> Accumulator:
    """Fold an iterable of :class:`ObservationSystem` chunks into an :class:`Accumulator`.

    Parameters
    ----------
    chunks : iterable of ObservationSystem
        E.g. the streaming chunk iterator of :func:`symoro_gen.observations.iter_chunks`.
    names : sequence of str, optional
        Column labels; taken from the first chunk when omitted.
    weighted : bool
        Apply each chunk's row weights.

    Returns
    -------
    Accumulator
    """
    acc = None if names is None else Accumulator.empty(names, weighted=weighted)
    for chunk in chunks:
        if acc is None:
            acc = Accumulator.empty(chunk.names, weighted=weighted)
        acc = acc.add(chunk)
    if acc is None:
        raise IdentificationError("accumulate: no chunks were given")
    return acc


def factor_system(system: ObservationSystem, use_weights: bool = False) -> Accumulator:
    """The per-joint factors of a whole system (as if streamed in one chunk)."""
    if not use_weights and system.weights is not None:
        system = ObservationSystem(system.W, system.Y, system.names, system.joint, None)
    return Accumulator.empty(system.names, system.n_joints, weighted=use_weights).add(system)
