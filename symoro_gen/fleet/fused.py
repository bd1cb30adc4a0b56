"""The fleet's per-log kernel: the assembly engine's decimated rows folded into per-joint QR factors,
streaming, so that the full-rate ``W`` of a log never exists in memory (the per-chunk kernel is the cost of
everything a fleet run does).

The rows are those of :func:`~symoro_gen.observations.iter_chunks` (Gautier's parallel decimation, RX-90
paper eq. 14-16), produced by the engine :func:`~symoro_gen.observations.fused.decimated_rows` (polyphase
FIR with state, only the distinct columns of ``W`` filtered, compiled gathers: see its module notes) in
their compact form (distinct columns, then ``Y``). What this module adds is the folding:

* **per-joint columns, in-place QR**: joint j's rows are non-zero only in the columns of its own entries
  (links j..n and its drive), so its factor is kept on those columns (exact) and the decimated rows are
  written scaled (compiled copy) into a Fortran-ordered ``[R_j; rows]`` buffer that LAPACK ``dgeqrf``
  factors in place every ``fold_rows`` rows (Golub & Van Loan, Matrix Computations, 4th ed., sec. 5.2,
  Householder QR; the stacking is the TSQR update of Demmel et al. 2012), every BLAS/LAPACK call of a
  log on the options' thread count (one by default).

Experiments the engine does not cover (:func:`~symoro_gen.observations.fused.fused_applies`: ``ftype="iir"``,
``n_d = 1``, ``min_velocity``, recorded derivatives, too short), payload columns, and logs recorded with the
payload (the assembly warns that its effect stays in the residual) go through
:func:`~symoro_gen.observations.iter_chunks` and :func:`~symoro_gen.identification.accumulate.accumulate`.
"""
from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from scipy.linalg import lapack

from ..errors import ShapeError
from ..identification.accumulate import Accumulator, accumulate
from ..model import IdentificationModel
from ..observations import AssemblyOptions, iter_chunks
from ..observations.fused import (
    BATCH_SUPER_ROWS,
    OUTER_SAMPLES,
    REGRESSOR_ROWS,
    ColumnMap,
    compiled_helpers,
    decimated_rows,
    filter_settings,
    fused_applies,
    model_column_map,
)
from ..preprocessing.filtering import blas_threads
from ..preprocessing.trajectory import Trajectory

__all__ = ["FOLD_ROWS", "fold_trajectories", "fold_trajectory"]

#: decimated rows per joint collected before one LAPACK QR folds them into R_j
FOLD_ROWS = 2048


class _Folder:
    """Folds decimated outputs ``(k, C)`` (distinct columns, then Y of every joint) into per-joint QR
    factors. Joint j's rows are non-zero only in the columns of its own entries of ``W`` (the parameters
    of links j..n and its drive), so its factor is kept on those columns only (``L_j + 1`` with Y) and
    embedded in the full ``(c+1, c+1)`` factor at the end (exact: the others are zero columns). Rows are
    written scaled straight into a Fortran-ordered ``[R_j; rows]`` buffer that LAPACK ``dgeqrf``
    factors in place every ``fold_rows`` rows."""

    def __init__(self, names: tuple[str, ...], cmap: ColumnMap, fold_rows: int, acc: Accumulator | None):
        self.names, self.cmap, self.fold_rows = names, cmap, max(1, int(fold_rows))
        self.acc = acc
        n, nb, U = cmap.n, cmap.nb, cmap.source.size
        joint, col = np.divmod(cmap.entry, nb)
        self.cols, self.src, self.scale, self.buf, self.lwork = [], [], [], [], []
        for j in range(n):
            sel = np.flatnonzero(joint == j)                     # entries sorted: columns ascending
            self.cols.append(col[sel])
            self.src.append(np.ascontiguousarray(np.append(cmap.column[sel], U + j), dtype=np.int64))  # Y last
            self.scale.append(np.ascontiguousarray(np.append(cmap.scale[sel], 1.0), dtype=float))
            L1 = sel.size + 1
            self.buf.append(np.zeros((L1 + self.fold_rows, L1), order="F"))
            self.lwork.append(max(1, int(lapack.dgeqrf_lwork(L1 + self.fold_rows, L1)[0])))
        kernels = compiled_helpers()
        self.scatter = None if kernels is None else kernels["scatter"]
        self.rows = 0                                            # rows in the buffers (same for every joint)
        self.total = [0] * n
        self.yy = [0.0] * n

    def add(self, y: np.ndarray) -> None:
        i = 0
        while i < y.shape[0]:
            take = min(y.shape[0] - i, self.fold_rows - self.rows)
            part = y[i:i + take]
            for j, buf in enumerate(self.buf):
                L1 = buf.shape[1]
                block = buf[L1 + self.rows:L1 + self.rows + take]
                if self.scatter is not None and part.flags.c_contiguous:
                    self.scatter(take, part.ctypes.data, part.shape[1], L1, self.src[j].ctypes.data,
                                 self.scale[j].ctypes.data, block.ctypes.data, buf.shape[0])
                else:
                    np.multiply(part[:, self.src[j]], self.scale[j], out=block)
                self.yy[j] += float(block[:, -1] @ block[:, -1])
                self.total[j] += take
            self.rows += take
            i += take
            if self.rows == self.fold_rows:
                self._fold()

    def _fold(self) -> None:
        for j, buf in enumerate(self.buf):
            L1 = buf.shape[1]
            qr, _, _, info = lapack.dgeqrf(buf, lwork=self.lwork[j], overwrite_a=1)
            if info != 0:
                raise ShapeError(f"LAPACK dgeqrf failed (info {info}) folding the rows of joint {j + 1}")
            buf[:L1] = np.triu(qr[:L1])                          # in place (F-ordered): qr is buf
        self.rows = 0

    def flush(self) -> None:
        if self.rows:
            for buf in self.buf:                                 # the unused rows are zero rows
                buf[buf.shape[1] + self.rows:] = 0.0
            self._fold()

    def result(self) -> Accumulator:
        """The factors so far (pending rows folded), merged with the accumulator given, if any."""
        self.flush()
        cm = self.cmap
        c1 = cm.nb + 1
        Rs = []
        for j, buf in enumerate(self.buf):
            idx = np.append(self.cols[j], cm.nb)
            R = np.zeros((c1, c1))
            R[np.ix_(np.arange(idx.size), idx)] = buf[:idx.size]
            Rs.append(R)
        new = Accumulator(self.names, tuple(Rs), tuple(self.total), tuple(self.yy))
        a = self.acc
        if a is None:
            return new
        nj = max(a.n_joints, new.n_joints)
        Rm, rows, yy = [], [], []
        for j in range(nj):
            parts = [x.R[j] for x in (a, new) if j < x.n_joints]
            Rj = np.asarray(np.linalg.qr(np.vstack(parts), mode="r")) if len(parts) > 1 else parts[0]
            Rm.append(Rj)
            rows.append(sum(x.rows[j] for x in (a, new) if j < x.n_joints))
            yy.append(sum(x.yy[j] for x in (a, new) if j < x.n_joints))
        return Accumulator(self.names, tuple(Rm), tuple(rows), tuple(yy), a.weighted)




def fold_trajectory(model: IdentificationModel, traj: Trajectory, options: AssemblyOptions | None = None,
                    acc: Accumulator | None = None, *, cmap: ColumnMap | None = None,
                    batch_super_rows: int = BATCH_SUPER_ROWS, outer_samples: int = OUTER_SAMPLES,
                    regressor_rows: int = REGRESSOR_ROWS,
                    fold_rows: int = FOLD_ROWS) -> Accumulator:
    """Fold one experiment into per-joint QR factors (the rows of ``iter_chunks``, see the module notes).

    Parameters
    ----------
    model : IdentificationModel
    traj : Trajectory
    options : AssemblyOptions, optional
        Filters (default: Gautier's rules per experiment); ``chunk_samples`` / ``max_chunk_mb`` bound the
        Butterworth blocks.
    acc : Accumulator, optional
        Factors to fold into (default: a new one).
    cmap : ColumnMap, optional
        :func:`~symoro_gen.observations.fused.column_map` of the model (computed once per model when not given).

    Returns
    -------
    Accumulator
    """
    opts = AssemblyOptions(keep_signals=False) if options is None else options
    # every BLAS and LAPACK call of the kernel with the options' threads (default 1), the rule's sums and the
    # last QR fold (result()) included: a multi-threaded OpenBLAS spent 0.4 s CPU on each 2k-row dgeqrf
    # here (0.004 s on one thread), which a process outside Dask's nanny (threads:N, the CLI) paid per log
    with blas_threads(opts.blas_threads):
        return _fold_one(model, traj, opts, acc, cmap, batch_super_rows, outer_samples, regressor_rows, fold_rows)


def _fold_one(model: IdentificationModel, traj: Trajectory, opts: AssemblyOptions, acc: Accumulator | None,
              cmap: ColumnMap | None, batch_super_rows: int, outer_samples: int, regressor_rows: int,
              fold_rows: int) -> Accumulator:
    st = filter_settings(traj, opts)
    if traj.loaded or opts.payload_columns or not fused_applies(traj, st, opts):
        chunks = iter_chunks(model, traj, opts, progress=False)
        if acc is None:
            return accumulate(chunks)
        for c in chunks:
            acc = acc.add(c)
        return acc
    names = tuple(model.BASE_NAMES)
    n = traj.n_joints
    if n != int(model.N_JOINTS):
        raise ShapeError(f"{traj.source}: trajectory has {n} joints, model {getattr(model, 'ROBOT', '?')} "
                         f"has {model.N_JOINTS}")
    if acc is not None and acc.names != names:
        raise ShapeError(f"{traj.source}: the accumulator's columns are not the model's base parameters")
    cm = cmap if cmap is not None else model_column_map(model, n, len(names))
    folder = _Folder(names, cm, fold_rows, acc)
    for y in decimated_rows(model, traj, st, opts, cm, batch_super_rows=batch_super_rows, outer_samples=outer_samples,
                            regressor_rows=regressor_rows):
        folder.add(y)
    return folder.result()


def fold_trajectories(model: IdentificationModel, trajectories: Iterable[Trajectory],
                      options: AssemblyOptions | None = None, *, cmap: ColumnMap | None = None) -> Accumulator:
    """:func:`fold_trajectory` over several experiments into one accumulator."""
    acc: Accumulator | None = None
    for tr in trajectories:
        if cmap is None:
            cmap = model_column_map(model, tr.n_joints, len(model.BASE_NAMES))
        acc = fold_trajectory(model, tr, options, acc, cmap=cmap)
    if acc is None:
        raise ShapeError("fold_trajectories: no experiment given")
    return acc
