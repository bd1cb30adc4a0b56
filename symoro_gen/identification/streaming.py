"""Identification data in bounded memory: the observation system folded into per-joint QR factors as it
is assembled, never held whole.

:func:`stream_assembly` runs the assembly stage (Gautier's filtering and parallel decimation, RX-90 paper
eq. 14-16; :func:`symoro_gen.observations.iter_chunks`) block after block and absorbs each block into an
:class:`~.accumulate.Accumulator` (per joint, the triangular factor ``R_j`` of ``[W_j  Y_j]``: TSQR). What
``identify`` computes from the whole system it computes from those factors, with the same numbers to
rounding (:mod:`.accumulate`):

* IDIM-OLS (RX-90 eq. 17-21): the solution, ``sigma_rho`` and the covariance from the stacked ``R_j``;
* IDIM-WLS (RX-90 eq. 22, Gautier's per-joint weighting): ``sigma_j`` from the joint-j OLS on ``R_j`` alone
  (its residual norm ``||Y_j||^2 - ||Q_j' Y_j||^2`` is the last diagonal entry of ``R_j``), then the stack of
  ``R_j / sigma_j``;
* IDIM-TLS (LWR4 paper eq. 12-16): the SVD of ``[W  -Y]`` is that of the stacked factors with the last
  column negated;
* the singular values of ``W`` (condition numbers) are those of the stacked factors; the per-joint error
  norms ``||Y_j - W_j chi|| = ||R_j [chi; -1]||``;
* a partly known payload (LWR4 paper eq. 7): the known columns moved to the right-hand side is a linear map
  of ``[W  Y]``, applied to ``R_j`` (:func:`fix_known`);
* the raw-torque error ``rel_err_raw``: a second pass over the recordings once ``chi`` is known, the model
  at full rate block after block (:func:`symoro_gen.observations.raw.raw_error_sums_streamed`).

The figures of a report use a thinned copy of the rows (:attr:`StreamedAssembly.sample`, at most
``SAMPLE_ROWS`` rows per joint, every ``stride``-th row), not the whole system. What needs the rows
themselves stays on the in-memory path (``symoro_gen.workflows.identify`` chooses): identified gains, the
physically consistent estimate, ``drop_saturated``; IDIM-IV and DIDIM simulate the robot.
"""
from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..errors import IdentificationError
from ..model import IdentificationModel
from ..observations.assembly import ExperimentReport, iter_chunks, metric_basis
from ..observations.options import AssemblyOptions
from ..observations.raw import raw_error_sums_streamed
from ..observations.system import ObservationSystem
from ..preprocessing.trajectory import Trajectory
from ..progress import ProgressArg
from .accumulate import Accumulator

__all__ = ["RAW_BATCH", "SAMPLE_ROWS", "STREAM_CHUNK_MB", "StreamedAssembly", "fix_known", "pad_columns", "stack_factors", "stream_assembly"]

#: rows per joint kept (every ``stride``-th one) for the figures of a streamed identification
SAMPLE_ROWS = 1024
#: ``AssemblyOptions.max_chunk_mb`` of a streamed identification: the engine's smallest Butterworth blocks
#: (``OUTER_SAMPLES``), so that what ``identify`` holds besides the recording is a few MB per joint
STREAM_CHUNK_MB = 8.0
#: samples per regressor call of the raw-torque pass (a (batch, n, nb) buffer)
RAW_BATCH = 2048


class _Thinner:
    """Every ``stride``-th row of each joint (stride doubled whenever a joint holds ``2 cap`` rows)."""

    def __init__(self, cap: int) -> None:
        self.cap, self.stride = max(1, int(cap)), 1
        self.count: dict[int, int] = {}
        self.W: dict[int, list[np.ndarray]] = {}
        self.Y: dict[int, list[np.ndarray]] = {}

    def add(self, chunk: ObservationSystem) -> None:
        for j in np.unique(chunk.joint):
            j = int(j)
            sel = np.flatnonzero(chunk.joint == j)
            k0 = self.count.get(j, 0)
            keep = sel[(k0 + np.arange(sel.size)) % self.stride == 0]
            self.count[j] = k0 + sel.size
            self.W.setdefault(j, []).append(chunk.W[keep])
            self.Y.setdefault(j, []).append(chunk.Y[keep])
        while max((sum(len(y) for y in ys) for ys in self.Y.values()), default=0) > 2 * self.cap:
            self._halve()

    def _halve(self) -> None:
        """Keep the rows whose index is a multiple of twice the stride (those kept are multiples of it)."""
        for j in self.Y:
            W, Y = np.concatenate(self.W[j]), np.concatenate(self.Y[j])
            self.W[j], self.Y[j] = [W[::2]], [Y[::2]]
        self.stride *= 2

    def system(self, names: Sequence[str], n_params: int) -> ObservationSystem:
        js = sorted(self.Y)
        if not js:
            return ObservationSystem(np.zeros((0, n_params)), np.zeros(0), tuple(names), np.zeros(0, int))
        W = np.concatenate([np.concatenate(self.W[j]) for j in js])
        Y = np.concatenate([np.concatenate(self.Y[j]) for j in js])
        J = np.concatenate([np.full(sum(len(y) for y in self.Y[j]), j) for j in js])
        return ObservationSystem(W, Y, tuple(names), J)


@dataclass(frozen=True, eq=False)
class StreamedAssembly:
    """The assembly of some recordings as per-joint QR factors (no ``W``, no full-rate signals kept).

    Attributes
    ----------
    accumulator : Accumulator
        Per-joint factors of ``[W_j  Y_j]`` (what the estimators take instead of the system).
    experiments : tuple of ExperimentReport
        What the assembly did with each recording (filters, rows per joint).
    options : AssemblyOptions
    trajectories : tuple of Trajectory
        The recordings (read again, block after block, by the raw-torque error).
    sample : ObservationSystem
        Every ``stride``-th row of each joint: the rows the figures of a report show.
    stride : int
    """

    accumulator: Accumulator
    experiments: tuple[ExperimentReport, ...]
    options: AssemblyOptions
    trajectories: tuple[Trajectory, ...]
    sample: ObservationSystem
    stride: int = 1

    @property
    def system(self) -> Accumulator:
        """The accumulator (what the estimators take; named as :attr:`Assembly.system`)."""
        return self.accumulator

    def metric_basis(self) -> dict[str, Any]:
        """:meth:`symoro_gen.observations.Assembly.metric_basis` (the JSON ``rel_err_basis``), same keys."""
        return metric_basis([e.settings for e in self.experiments], self.options, int(self.accumulator.n_rows),
                            int(sum(e.n_samples - 2 * e.settings.edge_samples for e in self.experiments)))

    def raw_error_sums(self, model: IdentificationModel, theta: Mapping[str, float], *,
                       gains: ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Per joint ``sum (g_j tau_j - tau_hat_j)^2`` and ``sum (g_j tau_j)^2`` over every full-rate sample
        (:func:`symoro_gen.observations.raw.raw_error_sums`, computed block after block)."""
        return raw_error_sums_streamed(model, theta, self.trajectories, self.options,
                                       [e.settings for e in self.experiments], gains=gains, batch=RAW_BATCH)


def stream_assembly(model: IdentificationModel, trajectories: Trajectory | Iterable[Trajectory],
                    options: AssemblyOptions | None = None, *, n_joints: int | None = None,
                    sample_rows: int = SAMPLE_ROWS, progress: ProgressArg = None) -> StreamedAssembly:
    """Assemble ``trajectories`` into per-joint QR factors, one block of rows at a time (see the module notes).

    Parameters
    ----------
    model : IdentificationModel
    trajectories : Trajectory or iterable of Trajectory
    options : AssemblyOptions, optional
        As :func:`symoro_gen.observations.assemble` (``keep_signals`` and ``drop_saturated`` do not apply:
        nothing full-rate is kept, and saturated rows are removed by the in-memory assembly only).
    n_joints : int, optional
        Joints of the factors (default: the model's).
    sample_rows : int
        Rows per joint kept for figures.

    Returns
    -------
    StreamedAssembly
    """
    opts = AssemblyOptions() if options is None else options
    if opts.drop_saturated:
        raise IdentificationError("drop_saturated removes rows of the whole system: use the in-memory assembly")
    trajs = (trajectories,) if isinstance(trajectories, Trajectory) else tuple(trajectories)
    if not trajs:
        raise IdentificationError("stream_assembly: no recording given")
    reports: list[ExperimentReport] = []
    acc: Accumulator | None = None
    thin = _Thinner(sample_rows)
    n = int(model.N_JOINTS) if n_joints is None else int(n_joints)
    for chunk in iter_chunks(model, trajs, opts, on_experiment=reports.append, progress=progress):
        if acc is None:
            acc = Accumulator.empty(chunk.names, n)
        acc = acc.add(chunk)
        thin.add(chunk)
    if acc is None:
        raise IdentificationError("stream_assembly: the recordings gave no rows")
    return StreamedAssembly(accumulator=acc, experiments=tuple(reports), options=opts, trajectories=trajs,
                            sample=thin.system(acc.names, acc.n_params), stride=thin.stride)


# ---------------------------------------------------------------------------- column operations on factors
def _refactor(M: np.ndarray) -> np.ndarray:
    """A square upper-triangular factor with the Gram matrix of ``M`` (``M'M = R'R``)."""
    k = M.shape[1]
    R = np.asarray(np.linalg.qr(M, mode="r"))
    if R.shape[0] < k:
        R = np.vstack([R, np.zeros((k - R.shape[0], k))])
    return R


def fix_known(acc: Accumulator, known: Mapping[str, float]) -> Accumulator:
    """The factors of ``[W_u  Y - W_k chi_k]`` from those of ``[W_u  W_k  Y]`` (LWR4 paper eq. 7: the known
    payload parameters moved to the right-hand side, :func:`~.systems.fix_parameters`).

    ``[W_u, Y - W_k chi_k] = [W Y] T`` with ``T`` the linear map keeping the unknown columns and taking
    ``Y - W_k chi_k``, so ``R_j T`` has the Gram matrix of the new rows; it is re-triangularised. ``yy``
    becomes ``||Y_j - W_kj chi_k||^2`` (the last column of ``R_j T``)."""
    bad = [k for k in known if k not in acc.names]
    if bad:
        raise IdentificationError(f"known parameters {bad} are not columns {acc.names}")
    keep = [i for i, nm in enumerate(acc.names) if nm not in known]
    c = acc.n_params
    T = np.zeros((c + 1, len(keep) + 1))
    for k, i in enumerate(keep):
        T[i, k] = 1.0
    T[c, -1] = 1.0
    for nm, v in known.items():
        T[acc.names.index(nm), -1] = -float(v)
    Rs, yy = [], []
    for R in acc.R:
        M = R @ T
        yy.append(float(M[:, -1] @ M[:, -1]))
        Rs.append(_refactor(M))
    return Accumulator(tuple(acc.names[i] for i in keep), tuple(Rs), acc.rows, tuple(yy), acc.weighted)


def pad_columns(acc: Accumulator, names: Sequence[str]) -> Accumulator:
    """``acc`` with the columns ``names`` in that order (zero columns for those it lacks: an unloaded
    experiment's payload columns, :func:`~.systems.stack_systems`)."""
    missing = [nm for nm in acc.names if nm not in names]
    if missing:
        raise IdentificationError(f"columns {missing} are not among {tuple(names)}")
    c1 = len(names) + 1
    Rs = []
    for R in acc.R:
        M = np.zeros((R.shape[0], c1))
        for i, nm in enumerate(acc.names):
            M[:, names.index(nm)] = R[:, i]
        M[:, -1] = R[:, -1]
        Rs.append(_refactor(M))
    return Accumulator(tuple(names), tuple(Rs), acc.rows, acc.yy, acc.weighted)


def stack_factors(a: Accumulator, b: Accumulator) -> Accumulator:
    """The factors of the two systems stacked (same columns, :func:`~.systems.stack_systems`): per joint,
    the triangular factor of ``[R_a; R_b]``."""
    if a.names != b.names:
        raise IdentificationError(f"stack_factors: columns differ ({a.names} vs {b.names})")
    nj = max(a.n_joints, b.n_joints)
    c1 = a.n_params + 1
    z = np.zeros((c1, c1))
    Ra = list(a.R) + [z] * (nj - a.n_joints)
    Rb = list(b.R) + [z] * (nj - b.n_joints)
    ra = list(a.rows) + [0] * (nj - a.n_joints)
    rb = list(b.rows) + [0] * (nj - b.n_joints)
    ya = list(a.yy) + [0.0] * (nj - a.n_joints)
    yb = list(b.yy) + [0.0] * (nj - b.n_joints)
    return Accumulator(a.names, tuple(_refactor(np.vstack([x, y])) for x, y in zip(Ra, Rb)),
                       tuple(x + y for x, y in zip(ra, rb)), tuple(x + y for x, y in zip(ya, yb)), a.weighted)
