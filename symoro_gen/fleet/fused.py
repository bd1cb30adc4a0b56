"""The fused per-chunk kernel of a fleet run: band-pass ``q``, evaluate the base regressor, low-pass and
decimate it and fold it into the per-joint QR factors, streaming, so that the full-rate ``W`` never
exists in memory (issue 12, "the per-chunk kernel is the cost of everything").

It computes the rows of :func:`~symoro_gen.observations.iter_chunks` with the default FIR decimation
(Gautier's parallel decimation, RX-90 paper eq. 14-16: zero-phase Butterworth of ``q``, central
differences, then the same ``20 n_d + 1``-tap Hamming FIR applied to ``Y`` and to every column of ``W``,
one sample in ``n_d`` kept, zero padding beyond the ends as ``resample_poly``), only cheaper:

* **polyphase FIR with state across blocks**: the samples are taken ``n_d`` at a time ("super-rows",
  ``X_s``, shape ``(n_d, C)``); with the taps cut in 21 phases ``H[p, r] = h[p n_d + r]``, output ``k``
  is ``y_k = sum_p (H X_{k+p})[p]``. One matrix product ``H (21 x n_d) @ [X_s ...]`` per batch of
  super-rows (one BLAS call over the batch, 42 flops per sample and column: the floor of a
  ``20 n_d + 1``-tap FIR is 40), and the 20 partial outputs that straddle a batch border are carried to
  the next batch, so no sample is evaluated or filtered twice (the blocked FIR of the assembly pays
  1.75x the floor and re-evaluates its margins);
* **only the distinct columns**: the structurally non-zero entries of ``W`` (per joint row) that are
  equal up to a constant factor for random states are equal for all states (analytic functions);
  only one of each is filtered, then scaled back after decimation (80x fewer rows);
* **in cache**: the regressor is evaluated ``REGRESSOR_ROWS`` samples at a time into a reused buffer
  that stays in L2, and its distinct columns copied straight into the layout of the matrix product
  (``BATCH_SUPER_ROWS`` super-rows per product);
* **fewer Householder passes**: decimated rows are collected and folded into ``R_j`` by one stacked QR
  of ``[R_j; rows]`` every ``fold_rows`` rows
  (:class:`~symoro_gen.identification.accumulate.Accumulator`).

The Butterworth filter of ``q`` is zero-phase (forward-backward), so it is applied per outer block of
samples with a settling margin at both ends, as :func:`~symoro_gen.observations.iter_chunks` does: its
rows equal those of this kernel to ~1e-10 relative at the block borders (the truncated transient),
exactly elsewhere. Options this kernel does not cover (``ftype="iir"``, ``n_d = 1``, ``min_velocity``,
payload columns, recorded derivatives) run through :func:`~symoro_gen.observations.iter_chunks`.
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import as_strided

from ..errors import ShapeError
from ..identification.accumulate import Accumulator, accumulate
from ..model import IdentificationModel
from ..observations import AssemblyOptions, ObservationSystem, iter_chunks, observation_settings
from ..preprocessing.filtering import (
    FilterSettings,
    blas_threads,
    butterworth_settle_samples,
    decimation_filter,
    filter_and_differentiate,
    min_filter_samples,
)
from ..preprocessing.trajectory import Trajectory

__all__ = ["BATCH_SUPER_ROWS", "ColumnMap", "column_map", "fold_trajectories", "fold_trajectory", "fused_applies"]

#: super-rows (``n_d`` samples each) per regressor call and matrix product: ~1-2 MB of buffers, in L2
BATCH_SUPER_ROWS = 64
#: samples per regressor call: its output (~1.8 MB for 7 joints x 64 columns) stays in L2 for the copy
REGRESSOR_ROWS = 512
#: full-rate samples per Butterworth block (the zero-phase filter's margins are paid once per block)
OUTER_SAMPLES = 65536
#: decimated rows per joint collected before one stacked QR folds them into R_j
FOLD_ROWS = 4096


@dataclass(frozen=True, eq=False)
class ColumnMap:
    """Which regressor entries are filtered: the flat ``(n, nb)`` entry of each distinct column
    (``source``) and, for every structurally non-zero entry (``entry``), its column among them
    (``column``) and the constant factor (``scale``)."""

    n: int
    nb: int
    source: np.ndarray
    entry: np.ndarray
    column: np.ndarray
    scale: np.ndarray


def column_map(model: IdentificationModel, n: int, nb: int, *, samples: int = 48, seed: int = 12345) -> ColumnMap:
    """The distinct non-zero columns of the base regressor, from random states in [-2, 2]: an entry that is
    zero, or a constant times another, for random states is so for every state (analytic functions of
    ``q, dq, ddq``; the zero test is the one of the assembly)."""
    rng = np.random.default_rng(seed)
    q, dq, ddq = (rng.uniform(-2.0, 2.0, (samples, n)) for _ in range(3))
    W = np.asarray(model.regressor(q, dq, ddq), float)
    if W.shape != (samples, n, nb):
        raise ShapeError(f"model.regressor returned shape {W.shape}, expected {(samples, n, nb)}")
    W = W.reshape(samples, n * nb)
    entry = np.flatnonzero(np.any(W != 0.0, axis=0))
    source: list[int] = []
    column = np.empty(entry.size, int)
    scale = np.empty(entry.size)
    norms = np.linalg.norm(W, axis=0)
    for i, c in enumerate(entry):
        x = W[:, c]
        for u, s_idx in enumerate(source):
            y = W[:, s_idx]
            s = float(x @ y) / float(y @ y)
            if np.linalg.norm(x - s * y) <= 1e-13 * norms[c]:
                column[i], scale[i] = u, s
                break
        else:
            column[i], scale[i] = len(source), 1.0
            source.append(int(c))
    return ColumnMap(n, nb, np.array(source, int), entry, column, scale)


def fused_applies(traj: Trajectory, st: FilterSettings, opts: AssemblyOptions, payload: bool = False) -> bool:
    """Whether :func:`fold_trajectory` computes this experiment itself (default FIR decimation, no row
    selection, no payload columns, filtered derivatives, long enough) rather than through ``iter_chunks``."""
    if st.ftype != "fir" or st.n_d < 2 or opts.min_velocity is not None or opts.payload_columns or payload:
        return False
    if opts.use_recorded_derivatives or traj.loaded:
        return False
    N = traj.n_samples
    nseg = N - 2 * st.edge_samples
    return min_filter_samples(st.order) <= N and nseg >= max(min_filter_samples(st.order, st.n_d, st.ftype), st.n_d)


def _polyphase(st: FilterSettings) -> np.ndarray:
    """``H[p, r] = h[p n_d + r]`` (21 x n_d, zero beyond the last tap) of the decimation FIR."""
    h = decimation_filter(st.n_d, ftype="fir", cutoff_ratio=st.cutoff_ratio)
    nd = st.n_d
    P = -(-h.size // nd)
    H = np.zeros(P * nd)
    H[:h.size] = h
    return H.reshape(P, nd)


class _Folder:
    """Collects decimated outputs ``(k, C)`` (distinct columns, then Y of every joint) and folds them
    into per-joint factors every ``fold_rows`` rows."""

    def __init__(self, names: tuple[str, ...], cmap: ColumnMap, fold_rows: int, acc: Accumulator | None):
        self.names, self.cmap, self.fold_rows = names, cmap, fold_rows
        self.acc = acc if acc is not None else Accumulator.empty(names, cmap.n)
        self.parts: list[np.ndarray] = []
        self.rows = 0

    def add(self, y: np.ndarray) -> None:
        if y.shape[0]:
            self.parts.append(y)
            self.rows += y.shape[0]
            if self.rows >= self.fold_rows:
                self.flush()

    def flush(self) -> None:
        if not self.rows:
            return
        y = np.concatenate(self.parts, axis=0) if len(self.parts) > 1 else self.parts[0]
        self.parts, self.rows = [], 0
        cm = self.cmap
        k, n, nb = y.shape[0], cm.n, cm.nb
        U = cm.source.size
        Wd = np.zeros((k, n * nb))
        Wd[:, cm.entry] = y[:, cm.column] * cm.scale
        # rows grouped per joint (the ObservationSystem layout of iter_chunks)
        W = Wd.reshape(k, n, nb).transpose(1, 0, 2).reshape(n * k, nb)
        Y = y[:, U:U + n].T.reshape(n * k)
        self.acc = self.acc.add(ObservationSystem(W=W, Y=Y, names=self.names, joint=np.repeat(np.arange(n), k)))


def _regressor(model: IdentificationModel, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray,
               out: np.ndarray) -> np.ndarray:
    """The base regressor into ``out`` (models whose ``regressor`` takes no ``out``: copied there)."""
    try:
        W = model.regressor(q, dq, ddq, out=out)  # type: ignore[call-arg]  # generated models take out=
    except TypeError:
        W = np.asarray(model.regressor(q, dq, ddq), float)
    if W is not out:
        if W.shape != out.shape:
            raise ShapeError(f"model.regressor returned shape {W.shape}, expected {out.shape}")
        out[...] = W
    return out


def _fold_fused(model: IdentificationModel, traj: Trajectory, st: FilterSettings, opts: AssemblyOptions,
                cmap: ColumnMap, folder: _Folder, batch_super_rows: int, outer_samples: int,
                regressor_rows: int) -> None:
    n, nb = cmap.n, cmap.nb
    nd, e, fs = st.n_d, st.edge_samples, st.fs
    N = traj.n_samples
    nseg = N - 2 * e
    H = _polyphase(st)
    P = H.shape[0]                         # 21 phases: output k uses super-rows k .. k + P - 1
    half = (P - 1) // 2                    # super-rows of zero padding before the segment (half = 10 n_d samples)
    n_out = -(-nseg // nd)
    n_data = n_out                         # super-rows holding samples: s = half .. half + n_out - 1
    U = cmap.source.size
    B = max(1, int(batch_super_rows))
    margin = butterworth_settle_samples(fs, st.cutoff_hz, st.order) + 2
    if opts.chunk_samples is not None:
        outer = max(1, int(opts.chunk_samples) // nd)
    else:
        outer = max(1, max(int(outer_samples), int(opts.max_chunk_mb * 1e6 / (8.0 * 4 * n))) // nd)
    outer = max(B, outer // B * B)
    Xw = np.zeros((B, nd, U))             # super-row b, sample r of the batch: Xw[b, r] (distinct W columns)
    Xy = np.zeros((B, nd, n))             # and the torques
    # Z of super-rows s0 - (P - 1) ... s1 - 1: the last P - 1 of the previous batch carried over (the state
    # across batches), then this batch's, written in place by the matrix product
    Zw, Zy = np.zeros((P - 1 + B, P, U)), np.zeros((P - 1 + B, P, n))
    R = max(1, min(int(regressor_rows), B * nd))
    Wbuf = np.empty((R, n, nb))
    Xw2 = Xw.reshape(B * nd, U)
    src = cmap.source
    k_next = 0                             # next output index to emit

    def outputs(i0: int, i1: int, Zs: tuple[np.ndarray, ...] = (Zw, Zy)) -> np.ndarray:
        """Outputs i0..i1-1 of the window: ``y_i = sum_p Z[i + p, p]`` (output k = s0 - half + i)."""
        out = []
        for Z in Zs:
            s_0, s_1, s_2 = Z.strides
            V = as_strided(Z, shape=(Z.shape[0] - P + 1, P, Z.shape[2]), strides=(s_0, s_0 + s_1, s_2),
                           writeable=False)
            out.append(V[i0:i1].sum(axis=1))
        return np.concatenate(out, axis=1)

    with blas_threads(opts.blas_threads):
        for o0 in range(0, n_data, outer):
            o1 = min(n_data, o0 + outer)
            a, b = o0 * nd, min(nseg, o1 * nd)                     # segment samples of this outer block
            lo, hi = max(0, e + a - margin), min(N, e + b + margin)
            qf, dq, ddq = filter_and_differentiate(traj.q[lo:hi], fs, st.cutoff_hz, st.order, source=traj.source)
            off = e + a - lo
            tau = np.asarray(traj.tau[e + a:e + b], float)
            for s0 in range(o0, o1, B):
                s1 = min(o1, s0 + B)
                nbt = s1 - s0
                m0, m1 = (s0 - o0) * nd, min(b - a, (s1 - o0) * nd)  # rows of this batch in the outer block
                m = m1 - m0
                if m < B * nd:                                      # the last batch: zeros beyond the segment
                    Xw[...] = 0.0
                    Xy[...] = 0.0
                for r0 in range(0, m, R):                           # regressor in cache-sized calls
                    r1 = min(m, r0 + R)
                    i0, i1 = off + m0 + r0, off + m0 + r1
                    Wb = _regressor(model, qf[i0:i1], dq[i0:i1], ddq[i0:i1], Wbuf[:r1 - r0])
                    np.take(Wb.reshape(r1 - r0, n * nb), src, axis=1, out=Xw2[r0:r1], mode="clip")
                Xy.reshape(B * nd, n)[:m] = tau[m0:m1]
                np.matmul(H, Xw, out=Zw[P - 1:])
                np.matmul(H, Xy, out=Zy[P - 1:])
                # outputs i < nbt are complete (their last super-row, s0 - half + i + half, is in this batch)
                k0 = s0 - half
                i_first = max(0, k_next - k0)
                if i_first < nbt:
                    folder.add(outputs(i_first, nbt))
                    k_next = k0 + nbt
                Zw[:P - 1] = Zw[nbt:nbt + P - 1]
                Zy[:P - 1] = Zy[nbt:nbt + P - 1]
        # the outputs left only lack zero-padding super-rows: with Z = 0 there, they are complete
        # (window index i is now output n_data - half + i)
        kp = n_data - half
        if n_out > k_next:
            tail = tuple(np.concatenate([Z[:P - 1], np.zeros((half + 1,) + Z.shape[1:])]) for Z in (Zw, Zy))
            folder.add(outputs(k_next - kp, n_out - kp, tail))


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
        :func:`column_map` of the model (computed when not given).

    Returns
    -------
    Accumulator
    """
    opts = AssemblyOptions(keep_signals=False) if options is None else options
    st = observation_settings(traj, opts)
    if not fused_applies(traj, st, opts):
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
    cm = cmap if cmap is not None else column_map(model, n, len(names))
    folder = _Folder(names, cm, fold_rows, acc)
    _fold_fused(model, traj, st, opts, cm, folder, batch_super_rows, outer_samples, regressor_rows)
    folder.flush()
    return folder.acc


def fold_trajectories(model: IdentificationModel, trajectories: Iterable[Trajectory],
                      options: AssemblyOptions | None = None, *, cmap: ColumnMap | None = None) -> Accumulator:
    """:func:`fold_trajectory` over several experiments into one accumulator."""
    acc: Accumulator | None = None
    for tr in trajectories:
        if cmap is None:
            cmap = column_map(model, tr.n_joints, len(model.BASE_NAMES))
        acc = fold_trajectory(model, tr, options, acc, cmap=cmap)
    if acc is None:
        raise ShapeError("fold_trajectories: no experiment given")
    return acc
