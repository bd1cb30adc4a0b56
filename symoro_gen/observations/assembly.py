"""The assembly stage: trajectories -> the observation system ``Y = W chi + rho`` with its provenance.

This implements the pre-processing of Gautier's identification method (M. Gautier, "Dynamic
identification of robots with power model", ICRA 1997; M. Gautier & S. Briot, "New method for global
identification of the joint drive gains of robots using a known inertial payload" (the RX-90 paper),
eq. 14-16: band-pass filtering of ``q`` and *parallel decimation* of ``Y`` and of every column of
``W``, so that the decimated system keeps the identity ``Y = W chi``; the LWR4 paper, Sec. IV, uses
the same procedure). One signature: :func:`assemble` and :func:`iter_chunks` take ``(model,
trajectories, options)`` with an :class:`~symoro_gen.observations.options.AssemblyOptions`.

For each experiment (one :class:`~symoro_gen.preprocessing.trajectory.Trajectory`, never mixed with
another one):

1. ``q`` is low-passed by a zero-phase Butterworth filter and differentiated by central differences
   (band-pass estimates of ``q, dq, ddq``, see :mod:`symoro_gen.preprocessing.filtering`);
   ``edge_samples`` samples are then dropped at both ends (filter edge effects);
2. the model's base regressor (columns ``model.BASE_NAMES``) and, with ``payload_columns=True``, its
   payload regressor (columns ``model.PAYLOAD_NAMES``; zeros for experiments without the payload,
   eq. 7 of the LWR4 paper) are evaluated on every remaining sample;
3. ``Y`` (the measured torques) and every column of ``W`` are decimated in parallel (same zero-phase
   low-pass, one sample in ``n_d`` kept), so ``Y = W chi`` still holds;
4. optionally (``min_velocity``) the rows of joint j that depend on samples where ``|dq_j| <
   min_velocity`` are removed: near zero velocity the Coulomb term ``sign(dq)`` of the filtered
   velocity does not match the physical friction (rests, reversals), and the decimation low-pass
   spreads that mismatch over the rows around it. A row is removed when more than ``slow_weight_tol``
   (1 %) of its filter's absolute weights fall on such samples (the FIR weights of ``20 n_d + 1``
   samples are also used to judge the rows of ``ftype="iir"``);
5. rows are grouped per joint: all rows of joint 1 (experiment after experiment), then joint 2...

The filter settings are chosen per experiment by :func:`~symoro_gen.preprocessing.filtering.choose_filter_settings`
unless given (``cutoff_hz``, ``n_d``, ``dynamics_bandwidth_hz``...). :func:`assemble`
returns them with the system (``Assembly.summary()``), the sample behind every row (experiment,
full-rate sample index, time, joint) and, with ``options.keep_signals``, the filtered signals of each
experiment (:class:`ExperimentSignals`) that the later stages need (diagnosis, raw-torque errors): they
never filter again.

:func:`iter_chunks` is the streaming variant: it processes each experiment in blocks of
samples with overlapping margins (the Butterworth transient, ~10 periods of the cut-off), so memory
stays bounded whatever the recording length, and yields :class:`ObservationSystem` chunks (rows
grouped per joint within each chunk). The rows of both come from one engine,
:func:`~symoro_gen.observations.fused.decimated_rows` (RX-90 paper eq. 14-16: polyphase FIR with state
across blocks, only the distinct columns of ``W`` filtered, the generated C regressor called in cache; the
fleet folds the same rows into QR factors), whenever it covers the experiment
(:func:`~symoro_gen.observations.fused.fused_applies`); the rows are those of one pass over the whole
experiment to ~1e-10 relative at block borders (the truncated Butterworth transient). What the engine
does not cover -- ``ftype="iir"`` (SciPy's/Matlab's default ``decimate``, a whole experiment in memory at
once), ``n_d = 1``, ``min_velocity`` (the rows' exposure to slow samples), recorded derivatives, the
payload regressor of a loaded experiment -- this module computes by its blocked path (zero-padded
overlapping buffers with the FIR half-length ``10 n_d`` as margin, dense FIR products, the structurally
zero columns of ``W`` neither copied nor filtered). :func:`assemble` is the concatenation of the chunks,
regrouped per joint.

Cost, measured on the shared 2-core machine (``bench/bench_engine_assembly.py``, load ~8): one hour of
simulated 7-joint data at 1 kHz (LWR4, 3.6 M samples, 64 base columns, ``n_d = 80``) is assembled by
:func:`assemble` as ``identify`` calls it (filters' rule, full-rate signals kept) in 8.8 s CPU (12.4 s with
the blocked path), 1.7x the fleet's kernel on the same log in the same run; streamed
(:func:`iter_chunks` into an accumulator, bounded memory) in 6.2 s (9.0 s), 1.2x the fleet's kernel.
"""
from __future__ import annotations

import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import signal

from ..errors import DataFileError, ModelError, Problem, ShapeError
from ..model import IdentificationModel
from ..preprocessing.filtering import (
    FilterSettings,
    blas_threads,
    butterworth_settle_samples,
    decimation_filter,
    filter_and_differentiate,
    fir_buffer_length,
    fir_decimate,
    fir_decimate_padded,
    fir_group_size,
    min_filter_samples,
)
from ..preprocessing.motion import saturation_mask
from ..preprocessing.trajectory import Trajectory
from ..progress import ProgressArg, ProgressCounter
from .fused import (
    decimated_rows,
    filter_settings,
    fused_applies,
    model_column_map,
    outer_super_rows,
    zero_phase_kinematics,
)
from .options import AssemblyOptions
from .system import ObservationSystem

__all__ = [
    "Assembly",
    "ExperimentReport",
    "ExperimentSignals",
    "assemble",
    "basis_text",
    "iter_chunks",
    "iter_kinematics",
    "merge_metric_basis",
    "metric_basis",
    "observation_settings",
]


@dataclass(frozen=True)
class ExperimentReport:
    """What the assembly did with one experiment.

    Attributes
    ----------
    index : int
        0-based position of the experiment in the input.
    source : str
        ``Trajectory.source``.
    loaded : bool
        Payload mounted.
    n_samples : int
        Samples in the recording.
    settings : FilterSettings
        Filters used.
    rows_per_joint : tuple of int
        Rows kept per joint (after decimation and velocity removal).
    removed_low_velocity : tuple of int
        Rows removed per joint by ``min_velocity``.
    removed_saturated : tuple of int
        Rows removed per joint by ``drop_saturated`` (empty without it).
    """

    index: int
    source: str
    loaded: bool
    n_samples: int
    settings: FilterSettings
    rows_per_joint: tuple[int, ...]
    removed_low_velocity: tuple[int, ...]
    removed_saturated: tuple[int, ...] = ()


def metric_basis(settings: Sequence[FilterSettings], options: AssemblyOptions, rows: int, samples: int) -> dict[str, Any]:
    """The JSON ``rel_err_basis``: what ``rel_err`` and ``rel_err_raw`` are computed on (the experiments'
    filter ``settings``, the assembly ``options``, the rows of the observation system and the full-rate
    samples of the raw error)."""
    return {
        "rel_err": "||Y_j - W_j chi|| / ||Y_j|| on the filtered, decimated observation system",
        "rel_err_raw": "||tau_j - IDM_j(q, dq, ddq) chi|| / ||tau_j||: the model at full rate on the "
                       "filtered states against the raw measured torque",
        "cutoff_hz": [float(s.cutoff_hz) for s in settings],
        "n_d": [int(s.n_d) for s in settings],
        "min_velocity": options.min_velocity,
        "rows": int(rows),
        "samples": int(samples),
    }


@dataclass(frozen=True, eq=False)
class ExperimentSignals:
    """The signals of one experiment as the assembly computed them (full rate, edge samples dropped).

    Attributes
    ----------
    index : int
        0-based position of the experiment in the input.
    source : str
    loaded : bool
    settings : FilterSettings
        The filters used (cut-off, ``n_d``, edge samples...).
    first : int
        Full-rate index, in the recording, of the first kept sample (``settings.edge_samples``).
    t : ndarray, shape (M,)
        Time of each kept sample, as recorded [s].
    q, dq, ddq : ndarray, shape (M, n)
        Band-pass estimates (zero-phase Butterworth of ``q`` then central differences; the recorded
        values with ``use_recorded_derivatives``) on which ``W`` was evaluated.
    q_raw : ndarray, shape (M, n)
        Measured positions.
    tau_raw : ndarray, shape (M, n)
        Measured torques, unfiltered: the reference of the raw-torque error ``rel_err_raw``.
    tau_rows : ndarray, shape (K, n)
        Measured torques of all joints low-passed and decimated in parallel with ``W`` (``Y`` of
        joint j is ``tau_rows[:, j]`` before any row removal), one row per decimated sample.
    decimated_samples : ndarray of int, shape (K,)
        Full-rate index, in the recording, of each decimated sample.
    """

    index: int
    source: str
    loaded: bool
    settings: FilterSettings
    first: int
    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    q_raw: np.ndarray
    tau_raw: np.ndarray
    tau_rows: np.ndarray
    decimated_samples: np.ndarray

    @property
    def n_samples(self) -> int:
        """Kept full-rate samples M."""
        return int(self.t.shape[0])


@dataclass(frozen=True, eq=False)
class Assembly:
    """An observation system with its provenance.

    Attributes
    ----------
    system : ObservationSystem
        ``W`` (r, c), ``Y`` (r,), column names, joint of each row (``system.joint``).
    experiments : tuple of ExperimentReport
    row_experiment : ndarray of int, shape (r,)
        Index of the experiment each row comes from.
    row_time : ndarray, shape (r,)
        Time [s] of each row's sample in its recording.
    row_sample : ndarray of int, shape (r,)
        Full-rate index, in its recording, of each row's (decimated) sample.
    row_index : ndarray of int, shape (r,)
        Index of each row's sample among the decimated samples of its experiment
        (``signals[e].tau_rows[row_index]``).
    options : AssemblyOptions
        The options it was built with.
    signals : tuple of ExperimentSignals
        Per experiment (empty when ``options.keep_signals`` is False).
    """

    system: ObservationSystem
    experiments: tuple[ExperimentReport, ...]
    row_experiment: np.ndarray
    row_time: np.ndarray
    row_sample: np.ndarray
    row_index: np.ndarray
    options: AssemblyOptions
    signals: tuple[ExperimentSignals, ...] = ()

    @property
    def row_joint(self) -> np.ndarray:
        """0-based joint of each row (``system.joint``)."""
        return self.system.joint

    @property
    def n_joints(self) -> int:
        return self.system.n_joints

    def metric_basis(self) -> dict[str, Any]:
        """What ``rel_err`` on this system is computed on: filter cut-off(s), decimation factor(s),
        rows, and the full-rate samples the raw error uses (the JSON ``rel_err_basis``)."""
        return metric_basis([e.settings for e in self.experiments], self.options, int(self.system.Y.size),
                            int(sum(s.n_samples for s in self.signals)))

    def summary(self) -> str:
        s = self.system
        lines = [f"Observation system: {s.W.shape[0]} rows x {s.W.shape[1]} columns, "
                 f"{s.n_joints} joints, {len(self.experiments)} experiment(s)"]
        for e in self.experiments:
            lines.append(f"\n[{e.index}] {e.source} ({'loaded' if e.loaded else 'unloaded'}, {e.n_samples} samples)")
            lines += ["    " + x for x in e.settings.summary().splitlines()]
            lines.append(f"    rows per joint: {', '.join(str(r) for r in e.rows_per_joint)}")
            if any(e.removed_low_velocity):
                lines.append(f"    removed (|dq| < min_velocity): {', '.join(str(r) for r in e.removed_low_velocity)}")
        return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
def _as_trajectories(trajectories: Trajectory | Iterable[Trajectory]) -> Iterable[Trajectory]:
    if isinstance(trajectories, Trajectory):
        return (trajectories,)
    return trajectories


def _sample_progress(progress: ProgressArg, trajectories: Trajectory | Iterable[Trajectory]) -> ProgressCounter:
    """Progress over the full-rate samples of the experiments (total known unless a lazy iterable)."""
    if isinstance(trajectories, Trajectory):
        total = trajectories.n_samples
    elif isinstance(trajectories, (list, tuple)):
        total = sum(t.n_samples for t in trajectories)
    else:
        total = None
    return ProgressCounter(progress, total=total, desc="assembling W", unit="sample", unit_scale=True)


def _blocks_with_progress(blocks: Iterable[_Block], n_samples: int, n_d: int,
                          step: Callable[[int], object]) -> Iterator[_Block]:
    """Pass the blocks of one experiment through, reporting its samples to ``step`` (they add up to
    ``n_samples`` once the experiment is done)."""
    done = 0
    for blk in blocks:
        inc = min(blk.Yd.shape[0] * n_d, n_samples - done)
        done += inc
        step(inc)
        yield blk
    step(n_samples - done)


def observation_settings(trajectory: Trajectory, options: AssemblyOptions | None = None) -> FilterSettings:
    """The :class:`FilterSettings` the assembly uses for ``trajectory`` with ``options``
    (Gautier's rules for the values left unset; :func:`~symoro_gen.observations.fused.filter_settings`)."""
    return filter_settings(trajectory, AssemblyOptions() if options is None else options)


def _names(model: IdentificationModel, payload_columns: bool) -> tuple[tuple[str, ...], int, int]:
    try:
        base = tuple(model.BASE_NAMES)
    except AttributeError:
        raise ModelError("model has no BASE_NAMES: pass a generated model (symoro_gen.load_model) "
                         "or symoro_gen.simulate.numeric_model(robot)") from None
    pay: tuple[str, ...] = ()
    if payload_columns:
        pay = tuple(getattr(model, "PAYLOAD_NAMES", ()))
        if not pay:
            raise ModelError(f"payload_columns=True but model {getattr(model, 'ROBOT', '?')} has no payload frame")
    return base + pay, len(base), len(pay)


class _SignalSink:
    """Full-rate buffers of one experiment's filtered kinematics (written block by block)."""

    def __init__(self, m: int, n: int):
        self.q = np.empty((m, n))
        self.dq = np.empty((m, n))
        self.ddq = np.empty((m, n))

    def write(self, a: int, b: int, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray) -> None:
        self.q[a:b], self.dq[a:b], self.ddq[a:b] = q, dq, ddq


@dataclass
class _Block:
    Wd: np.ndarray  # (k, n, c)
    Yd: np.ndarray  # (k, n)
    slow: np.ndarray | None  # (k, n): share of each row's filter weight on samples with |dq_j| < min_velocity_j
    idx: np.ndarray  # (k,) full-rate sample index in the recording


def _slow_indicator(dq: np.ndarray, vmin: np.ndarray, valid: slice) -> np.ndarray:
    """1.0 where |dq_j| < vmin_j on the valid rows, 0.0 elsewhere (zero padding is not 'slow')."""
    out = np.zeros(dq.shape)
    out[valid] = np.abs(dq[valid]) < vmin
    return out


class _Evaluator:
    """Calls a model's regressors into reused arrays and keeps only its structurally non-zero columns.

    The columns of ``W`` (per joint row) that are zero for random states are zero for all states
    (the entries are analytic functions of q, dq, ddq, or literal zeros); they are neither copied nor
    filtered.
    """

    def __init__(self, model: IdentificationModel, n: int, nb: int, npay: int, batch: int, rng_seed: int = 12345):
        self.model, self.n, self.nb, self.npay, self.batch = model, n, nb, npay, batch
        rng = np.random.default_rng(rng_seed)
        q, dq, ddq = (rng.uniform(-2.0, 2.0, (16, n)) for _ in range(3))
        self.out_ok: dict[str, bool] = {}
        Wb = self._call("regressor", q, dq, ddq, nb)
        self.nz_base = np.flatnonzero(np.any(Wb.reshape(16, n * nb) != 0.0, axis=0))
        if npay:
            Wp = self._call("payload_regressor", q, dq, ddq, npay)
            self.nz_pay = np.flatnonzero(np.any(Wp.reshape(16, n * npay) != 0.0, axis=0))
        else:
            self.nz_pay = np.zeros(0, int)
        self._tmp: dict[str, np.ndarray] = {}

    def _call(self, what: str, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, ncol: int,
              out: np.ndarray | None = None) -> np.ndarray:
        fn = getattr(self.model, what)
        if out is not None and self.out_ok.get(what, True):
            try:
                W = fn(q, dq, ddq, out=out)
                self.out_ok[what] = True
            except TypeError:
                self.out_ok[what] = False
                W = fn(q, dq, ddq)
        else:
            W = fn(q, dq, ddq)
        W = np.asarray(W, float)
        if W.shape != (q.shape[0], self.n, ncol):
            raise ShapeError(f"model.{what} returned shape {W.shape}, expected {(q.shape[0], self.n, ncol)}")
        return W

    def columns(self, payload_on: bool) -> np.ndarray:
        """Flat indices into ``(n, nb + npay)`` of the columns kept for an experiment."""
        c = self.nb + self.npay
        j, i = np.divmod(self.nz_base, self.nb)
        cols = [j * c + i]
        if payload_on:
            j, i = np.divmod(self.nz_pay, self.npay)
            cols.append(j * c + self.nb + i)
        return np.concatenate(cols)

    def write(self, dst_base: np.ndarray, dst_pay: np.ndarray | None, q: np.ndarray, dq: np.ndarray,
              ddq: np.ndarray) -> None:
        """Kept columns of W on samples (q, dq, ddq): base ones into ``dst_base`` (m, nz_base.size),
        payload ones into ``dst_pay`` (m, nz_pay.size) when given (C-contiguous row blocks)."""
        m = q.shape[0]
        for s in range(0, m, self.batch):
            s2 = min(m, s + self.batch)
            k = s2 - s
            tb = self._tmp.get("b")
            if tb is None or tb.shape[0] < k:
                tb = self._tmp["b"] = np.empty((max(k, self.batch), self.n, self.nb))
            Wb = self._call("regressor", q[s:s2], dq[s:s2], ddq[s:s2], self.nb, out=tb[:k])
            np.take(Wb.reshape(k, -1), self.nz_base, axis=1, out=dst_base[s:s2], mode="clip")
            if dst_pay is not None:
                tp = self._tmp.get("p")
                if tp is None or tp.shape[0] < k:
                    tp = self._tmp["p"] = np.empty((max(k, self.batch), self.n, self.npay))
                Wp = self._call("payload_regressor", q[s:s2], dq[s:s2], ddq[s:s2], self.npay, out=tp[:k])
                np.take(Wp.reshape(k, -1), self.nz_pay, axis=1, out=dst_pay[s:s2], mode="clip")


def _experiment_blocks(model: IdentificationModel, traj: Trajectory, st: FilterSettings, opts: AssemblyOptions,
                       ev: _Evaluator, sink: _SignalSink | None = None) -> Iterator[_Block]:
    """Decimated blocks of one experiment (before velocity removal and regrouping); the filtered
    kinematics go to ``sink`` when given. A generator: the experiment is checked when the first block
    is asked for. The engine (:func:`~symoro_gen.observations.fused.decimated_rows`) computes them
    whenever it covers the experiment (:func:`~symoro_gen.observations.fused.fused_applies`), the blocked
    path of :class:`_ExperimentBlocks` otherwise."""
    if fused_applies(traj, st, opts):
        yield from _fused_blocks(model, traj, st, opts, ev, sink)
    else:
        yield from _ExperimentBlocks(model, traj, st, opts, ev, sink).blocks()


def _fused_blocks(model: IdentificationModel, traj: Trajectory, st: FilterSettings, opts: AssemblyOptions,
                  ev: _Evaluator, sink: _SignalSink | None) -> Iterator[_Block]:
    """The engine's compact rows (distinct columns of ``W``, then ``Y``) expanded into blocks: every
    structurally non-zero entry of ``W`` is its distinct column times its factor (the columns of the
    payload, for an experiment without it, stay zero as in the blocked path)."""
    if traj.n_joints != ev.n:
        raise ShapeError(f"{traj.source}: trajectory has {traj.n_joints} joints, model "
                         f"{getattr(model, 'ROBOT', '?')} has {ev.n}")
    cm = model_column_map(model, ev.n, ev.nb)
    n, c, U = ev.n, ev.nb + ev.npay, cm.source.size
    joint, col = np.divmod(cm.entry, cm.nb)
    dst = joint * c + col                                    # flat (n, c) index of each entry
    k0 = 0
    for y in decimated_rows(model, traj, st, opts, cm, sink=None if sink is None else sink.write):
        k = y.shape[0]
        Wd = np.zeros((k, n * c))
        Wd[:, dst] = y[:, cm.column] * cm.scale
        idx = st.edge_samples + np.arange(k0, k0 + k) * st.n_d
        k0 += k
        yield _Block(Wd=Wd.reshape(k, n, c), Yd=np.ascontiguousarray(y[:, U:]), slow=None, idx=idx)


class _ExperimentBlocks:
    """The blocks of one experiment: their layout (FIR decimation: zero-padded overlapping buffers; IIR: the
    whole experiment at once; no decimation: plain chunks), the kinematics filtered per block, and the
    buffers of W (kept columns), Y and dq reused for every block."""

    def __init__(self, model: IdentificationModel, traj: Trajectory, st: FilterSettings, opts: AssemblyOptions,
                 ev: _Evaluator, sink: _SignalSink | None) -> None:
        self.traj, self.st, self.opts, self.ev, self.sink = traj, st, opts, ev, sink
        n = self.n = traj.n_joints
        N = self.N = traj.n_samples
        src = traj.source
        if n != ev.n:
            raise ShapeError(f"{src}: trajectory has {n} joints, model {getattr(model, 'ROBOT', '?')} has {ev.n}")
        self.use_rec = opts.use_recorded_derivatives
        # joints whose position is constant (held still): exactly zero velocity and acceleration, not the
        # filter's rounding (whose sign would excite the Coulomb friction column)
        self.const = np.flatnonzero(np.ptp(traj.q, axis=0) == 0) if traj.n_samples else np.zeros(0, int)
        if self.use_rec and (traj.dq is None or traj.ddq is None):
            raise DataFileError([Problem(src, "", "dq/ddq", "use_recorded_derivatives=True but the trajectory has "
                                         "no recorded velocities/accelerations")])
        e = self.e = st.edge_samples
        nd = self.nd = st.n_d
        self.Nseg = N - 2 * e
        need = max(min_filter_samples(st.order, nd, st.ftype), nd)
        if min_filter_samples(st.order) > N or self.Nseg < need:
            raise DataFileError([Problem(src, f"rows 1-{N}", "", f"too short to filter and decimate: {N} samples, "
                                         f"{2 * e} dropped at the edges, at least {need} must remain "
                                         f"(cut-off {st.cutoff_hz:.4g} Hz, n_d = {nd})")])
        self.c = ev.nb + ev.npay
        self.payload_on = ev.npay > 0 and traj.loaded
        self.keep = ev.columns(self.payload_on)  # flat (n, c) indices of the buffer's W columns
        self.margin = 0 if self.use_rec else butterworth_settle_samples(st.fs, st.cutoff_hz, st.order) + 2
        self.fir = nd > 1 and st.ftype == "fir"
        self.iir = nd > 1 and st.ftype == "iir"
        self.h = np.zeros(0)
        self.L = self.half = 0
        self.group = 1
        if self.fir:
            self.h = decimation_filter(nd, ftype="fir", cutoff_ratio=st.cutoff_ratio)
            self.L = self.h.size
            self.half = (self.L - 1) // 2
            self.group = fir_group_size(nd)
        self.n_out_total = -(-self.Nseg // nd)
        self.per_block = self._outputs_per_block(self.keep.size + n)
        self.vmin = opts.velocity_threshold(n)
        self.habs: np.ndarray | None = None
        if self.vmin is not None and nd > 1:
            # weights of the decimation filter, normalised, to measure each row's exposure to slow samples
            habs = np.abs(decimation_filter(nd, ftype="fir", cutoff_ratio=st.cutoff_ratio))
            self.habs = habs / habs.sum()

    def _outputs_per_block(self, Cb: int) -> int:
        """Decimated outputs per block (``Cb`` buffer columns: kept W columns, then Y)."""
        opts, nd = self.opts, self.nd
        budget_rows = max(1, int(opts.max_chunk_mb * 1e6 / (8.0 * Cb)))
        if self.iir:
            per_block = self.n_out_total
        elif opts.chunk_samples is not None:
            per_block = max(1, int(opts.chunk_samples) // nd)
        elif self.fir:
            per_block = max(1, (budget_rows - self.L) // nd)
        else:
            per_block = budget_rows
        if self.fir:
            per_block = max(self.group, per_block // self.group * self.group)
        return min(per_block, self.n_out_total)

    def kinematics(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q, dq, ddq on segment samples [a, b)."""
        traj, st = self.traj, self.st
        lo_full, hi_full = self.e + a, self.e + b
        if self.use_rec:
            assert traj.dq is not None and traj.ddq is not None  # checked in __init__
            return traj.q[lo_full:hi_full], traj.dq[lo_full:hi_full], traj.ddq[lo_full:hi_full]
        lo = max(0, lo_full - self.margin)
        hi = min(self.N, hi_full + self.margin)
        qf, dq, ddq = filter_and_differentiate(traj.q[lo:hi], st.fs, st.cutoff_hz, st.order, source=traj.source)
        if self.const.size:
            qf[:, self.const] = traj.q[0, self.const]
            dq[:, self.const] = 0.0
            ddq[:, self.const] = 0.0
        s = slice(lo_full - lo, hi_full - lo)
        return qf[s], dq[s], ddq[s]

    def fill(self, bufs: list[np.ndarray], dqbuf: np.ndarray | None, r0: int, a: int, b: int) -> None:
        """W (kept columns), Y and dq of segment samples [a, b) into rows [r0, r0 + b - a)."""
        q, dq, ddq = self.kinematics(a, b)
        r1 = r0 + b - a
        self.ev.write(bufs[0][r0:r1], bufs[1][r0:r1] if self.payload_on else None, q, dq, ddq)
        bufs[-1][r0:r1] = self.traj.tau[self.e + a:self.e + b]
        if dqbuf is not None:
            dqbuf[r0:r1] = dq
        if self.sink is not None:
            self.sink.write(a, b, q, dq, ddq)

    def unpack(self, decs: list[np.ndarray], k: int) -> tuple[np.ndarray, np.ndarray]:
        Wd = np.zeros((k, self.n * self.c))
        Wd[:, self.keep] = np.concatenate(decs[:-1], axis=1)
        return Wd.reshape(k, self.n, self.c), decs[-1]

    def blocks(self) -> Iterator[_Block]:
        ev, n, nd = self.ev, self.n, self.nd
        if self.fir:
            rows_max = fir_buffer_length(self.per_block, nd, self.L, self.group)
        elif self.iir:
            rows_max = self.Nseg
        else:
            rows_max = self.per_block
        widths = [ev.nz_base.size] + ([ev.nz_pay.size] if self.payload_on else []) + [n]
        bufs = [np.empty((rows_max, w)) for w in widths]  # base W, payload W, Y: reused for every block
        dqbuf = np.empty((rows_max, n)) if self.vmin is not None else None
        for k0 in range(0, self.n_out_total, self.per_block):
            k1 = min(self.n_out_total, k0 + self.per_block)
            k = k1 - k0
            if self.fir:
                decs, slow = self._fir_block(bufs, dqbuf, k0, k1)
            elif self.iir:
                decs, slow = self._iir_block(bufs, dqbuf)
            else:
                Bs = [x[:k] for x in bufs]
                self.fill(Bs, dqbuf, 0, k0, k1)
                slow = _slow_indicator(dqbuf[:k], self.vmin, slice(0, k)) \
                    if self.vmin is not None and dqbuf is not None else None
                decs = [x.copy() for x in Bs]
            Wd, Yd = self.unpack(decs, k)
            idx = self.e + np.arange(k0, k1) * nd
            yield _Block(Wd=Wd, Yd=Yd, slow=slow, idx=idx)

    def _fir_block(self, bufs: list[np.ndarray], dqbuf: np.ndarray | None, k0: int, k1: int
                   ) -> tuple[list[np.ndarray], np.ndarray | None]:
        """Outputs [k0, k1) of the FIR decimation: the zero-padded buffer rows they need, filled and filtered."""
        nd, h, group, half, vmin, habs = self.nd, self.h, self.group, self.half, self.vmin, self.habs
        k = k1 - k0
        start = k0 * nd - half  # segment index of buffer row 0
        rows = fir_buffer_length(k, nd, self.L, group)
        a = max(0, start)
        b = min(self.Nseg, (k1 - 1) * nd + half + 1)
        r0, r1 = a - start, b - start
        Bs = [x[:rows] for x in bufs]
        for x in Bs:  # zero padding beyond the experiment's ends (as resample_poly)
            x[:r0] = 0.0
            x[r1:] = 0.0
        self.fill(Bs, dqbuf, r0, a, b)
        with blas_threads(self.opts.blas_threads):
            decs = [fir_decimate_padded(x, h, nd, k, group) for x in Bs]
            slow = fir_decimate_padded(_slow_indicator(dqbuf[:rows], vmin, slice(r0, r1)), habs, nd, k, group) \
                if vmin is not None and dqbuf is not None and habs is not None else None
        return decs, slow

    def _iir_block(self, bufs: list[np.ndarray], dqbuf: np.ndarray | None
                   ) -> tuple[list[np.ndarray], np.ndarray | None]:
        """The whole experiment through the IIR decimation filter (forward and backward)."""
        nd, vmin, habs = self.nd, self.vmin, self.habs
        self.fill(bufs, dqbuf, 0, 0, self.Nseg)
        with blas_threads(self.opts.blas_threads):
            slow = fir_decimate(_slow_indicator(dqbuf, vmin, slice(0, self.Nseg)), habs, nd) \
                if vmin is not None and dqbuf is not None and habs is not None else None
        sos = decimation_filter(nd, ftype="iir", cutoff_ratio=self.st.cutoff_ratio)
        return [signal.sosfiltfilt(sos, x, axis=0)[::nd] for x in bufs], slow


def iter_kinematics(model: IdentificationModel, traj: Trajectory, options: AssemblyOptions | None = None,
                    settings: FilterSettings | None = None
                    ) -> Iterator[tuple[int, int, np.ndarray, np.ndarray, np.ndarray]]:
    """The filtered kinematics of one experiment, block after block, as the assembly evaluates ``W`` on them
    (:attr:`ExperimentSignals.q`, ``dq``, ``ddq`` without keeping them: bounded memory).

    Yields
    ------
    (a, b, q, dq, ddq)
        Segment samples ``[a, b)`` (counted from ``settings.edge_samples``; the blocks follow each other and
        cover the segment once) and their band-pass ``q, dq, ddq`` (or the recorded derivatives). The blocks
        are the engine's Butterworth blocks (:func:`~symoro_gen.observations.fused.outer_super_rows`), so the
        numbers are those of ``keep_signals``; on the blocked path they equal them to the Butterworth
        transient's ~1e-10 relative at block borders.
    """
    opts = AssemblyOptions() if options is None else options
    st = observation_settings(traj, opts) if settings is None else settings
    _, nb, npay = _names(model, opts.payload_columns)
    n = traj.n_joints
    nseg = traj.n_samples - 2 * st.edge_samples
    if fused_applies(traj, st, opts):
        step = outer_super_rows(st, opts, n) * st.n_d
        for a in range(0, nseg, step):
            b = min(nseg, a + step)
            yield (a, b, *zero_phase_kinematics(traj, st, a, b))
        return
    ev = _Evaluator(model, n, nb, npay, opts.regressor_batch)
    blk = _ExperimentBlocks(model, traj, st, opts, ev, None)
    step = blk.Nseg if blk.iir else max(1, blk.per_block * blk.nd)
    for a in range(0, blk.Nseg, step):
        b = min(blk.Nseg, a + step)
        yield (a, b, *blk.kinematics(a, b))


def _stack_per_joint(blocks: list[tuple[_Block, int]], n: int, tol: float, removed: np.ndarray
                     ) -> tuple[list[np.ndarray], ...]:
    """Stack blocks (each tagged with its experiment) per joint, removing low-velocity rows.

    Returns lists (per joint and block) of W rows, Y, joint, experiment, full-rate sample index and
    decimated-sample index within the block."""
    Ws, Ys, Js, Es, Ss, Ks = [], [], [], [], [], []
    for j in range(n):
        for blk, ex in blocks:
            keep = np.ones(blk.Yd.shape[0], bool)
            if blk.slow is not None:
                keep = blk.slow[:, j] <= tol
                removed[ex, j] += int((~keep).sum())
            W = blk.Wd[keep, j, :]
            Ws.append(W)
            Ys.append(blk.Yd[keep, j])
            Js.append(np.full(W.shape[0], j))
            Es.append(np.full(W.shape[0], ex))
            Ss.append(blk.idx[keep])
            Ks.append(np.flatnonzero(keep))
    return Ws, Ys, Js, Es, Ss, Ks


def _check_loaded(traj: Trajectory, payload_columns: bool) -> None:
    if traj.loaded and not payload_columns:
        warnings.warn(f"{traj.source}: the payload is mounted but payload_columns=False: its effect stays in "
                      "the residual", UserWarning, stacklevel=4)


def iter_chunks(
    model: IdentificationModel,
    trajectories: Trajectory | Iterable[Trajectory],
    options: AssemblyOptions | None = None,
    *,
    on_experiment: Callable[[ExperimentReport], None] | None = None,
    progress: ProgressArg = None,
) -> Iterator[ObservationSystem]:
    """Stream the observation system in chunks of bounded memory (RX-90 paper eq. 14-16).

    Parameters
    ----------
    model : IdentificationModel
        Generated model (``symoro_gen.load_model(name)``) or any object with ``N_JOINTS``,
        ``BASE_NAMES``, ``regressor(q, dq, ddq) -> (N, n, nb)`` and, for payload columns,
        ``PAYLOAD_NAMES``, ``payload_regressor(q, dq, ddq) -> (N, n, 10)``.
    trajectories : Trajectory or iterable of Trajectory
        Experiments; may be a lazy iterable (each is read when reached).
    options : AssemblyOptions, optional
        Filters, decimation, row selection, chunking (default: the papers' rules for everything);
        ``keep_signals`` is ignored (nothing full-rate is kept).
    on_experiment : callable, optional
        Called with the :class:`ExperimentReport` of each experiment once it is done.
    progress : None, bool or callable
        None: a bar over the samples when the ambient mode allows it (the command line, see
        :mod:`symoro_gen.progress`); False: none; a callable: called with the number of full-rate
        samples just processed (they add up to each experiment's ``n_samples``).

    Yields
    ------
    ObservationSystem
        Rows of one block of one experiment, grouped per joint; ``names`` = ``BASE_NAMES``
        (+ ``PAYLOAD_NAMES``).
    """
    opts = AssemblyOptions() if options is None else options
    if opts.drop_saturated:
        raise ValueError("AssemblyOptions.drop_saturated: rows are removed by assemble(), not by iter_chunks()")
    names, nb, npay = _names(model, opts.payload_columns)
    ev = None
    prog = _sample_progress(progress, trajectories)
    for ex, traj in enumerate(_as_trajectories(trajectories)):
        if ev is None:
            ev = _Evaluator(model, traj.n_joints, nb, npay, opts.regressor_batch)
        _check_loaded(traj, opts.payload_columns)
        st = observation_settings(traj, opts)
        n = traj.n_joints
        opts.velocity_threshold(n)  # validates
        removed = np.zeros((ex + 1, n), int)
        kept = np.zeros(n, int)
        for blk in _blocks_with_progress(_experiment_blocks(model, traj, st, opts, ev), traj.n_samples, st.n_d,
                                         prog.step):
            Ws, Ys, Js, *_ = _stack_per_joint([(blk, ex)], n, opts.slow_weight_tol, removed)
            kept += np.array([w.shape[0] for w in Ws])
            yield ObservationSystem(W=np.concatenate(Ws, axis=0), Y=np.concatenate(Ys), names=names,
                                    joint=np.concatenate(Js))
        if on_experiment is not None:
            on_experiment(ExperimentReport(index=ex, source=traj.source, loaded=traj.loaded, n_samples=traj.n_samples,
                                           settings=st, rows_per_joint=tuple(int(x) for x in kept),
                                           removed_low_velocity=tuple(int(x) for x in removed[ex])))
    prog.close()


def assemble(
    model: IdentificationModel,
    trajectories: Trajectory | Sequence[Trajectory],
    options: AssemblyOptions | None = None,
    *,
    progress: ProgressArg = None,
) -> Assembly:
    """The whole observation system with its provenance and, with ``options.keep_signals``, the
    filtered signals of every experiment (same parameters as :func:`iter_chunks`).

    Returns
    -------
    Assembly
        ``system`` (rows grouped per joint over all experiments), per-experiment reports with the
        filter settings, the experiment, sample, time and joint of each row, and the
        :class:`ExperimentSignals`.
    """
    opts = AssemblyOptions() if options is None else options
    names, nb, npay = _names(model, opts.payload_columns)
    trajs = list(_as_trajectories(trajectories))
    if not trajs:
        raise ValueError("no trajectory given")
    n = trajs[0].n_joints
    for tr in trajs:
        if tr.n_joints != n:
            raise ShapeError(f"{tr.source}: {tr.n_joints} joints, {trajs[0].source}: {n}")
    opts.velocity_threshold(n)  # validates
    removed = np.zeros((len(trajs), n), int)
    ev = _Evaluator(model, n, nb, npay, opts.regressor_batch)
    blocks: list[tuple[_Block, int]] = []
    offsets: list[int] = []     # decimated-sample index of each block's first row within its experiment
    settings = []
    signals = []
    prog = _sample_progress(progress, trajs)
    for ex, traj in enumerate(trajs):
        _check_loaded(traj, opts.payload_columns)
        st = observation_settings(traj, opts)
        settings.append(st)
        e, N = st.edge_samples, traj.n_samples
        sink = _SignalSink(max(N - 2 * e, 0), n) if opts.keep_signals else None
        mine = [b for b in _blocks_with_progress(_experiment_blocks(model, traj, st, opts, ev, sink),
                                                 traj.n_samples, st.n_d, prog.step)]
        k0 = 0
        for b in mine:
            blocks.append((b, ex))
            offsets.append(k0)
            k0 += b.Yd.shape[0]
        if sink is not None:
            seg = slice(e, N - e)
            signals.append(ExperimentSignals(
                index=ex, source=traj.source, loaded=traj.loaded, settings=st, first=e,
                t=np.asarray(traj.t[seg], float), q=sink.q, dq=sink.dq, ddq=sink.ddq,
                q_raw=np.asarray(traj.q[seg], float), tau_raw=np.asarray(traj.tau[seg], float),
                tau_rows=np.concatenate([b.Yd for b in mine], axis=0),
                decimated_samples=np.concatenate([b.idx for b in mine])))
    prog.close()
    Ws, Ys, Js, Es, Ss, Ks = _stack_per_joint(blocks, n, opts.slow_weight_tol, removed)
    nblk = len(blocks)
    Ks = [k + offsets[i % nblk] for i, k in enumerate(Ks)]   # block-local -> experiment decimated index
    E = np.concatenate(Es)
    J = np.concatenate(Js)
    S = np.concatenate(Ss).astype(int)
    Wall, Yall, Kall = np.concatenate(Ws, axis=0), np.concatenate(Ys), np.concatenate(Ks).astype(int)
    sat_removed: list[tuple[int, ...]] = [()] * len(trajs)
    if opts.drop_saturated:
        drop = _saturated_rows(trajs, settings, E, J, S, opts)
        sat_removed = [tuple(int(np.sum(drop & (ex == E) & (j == J))) for j in range(n)) for ex in range(len(trajs))]
        Wall, Yall, Kall, E, J, S = (a[~drop] for a in (Wall, Yall, Kall, E, J, S))
    system = ObservationSystem(W=Wall, Y=Yall, names=names, joint=J)
    reports = []
    for ex, traj in enumerate(trajs):
        rows = tuple(int(np.sum((ex == E) & (j == J))) for j in range(n))
        reports.append(ExperimentReport(index=ex, source=traj.source, loaded=traj.loaded, n_samples=traj.n_samples,
                                        settings=settings[ex], rows_per_joint=rows,
                                        removed_low_velocity=tuple(int(x) for x in removed[ex]),
                                        removed_saturated=sat_removed[ex]))
    row_time = np.empty(S.size)
    for ex, traj in enumerate(trajs):
        m = ex == E
        row_time[m] = np.asarray(traj.t, float)[S[m]]
    return Assembly(system=system, experiments=tuple(reports), row_experiment=E, row_time=row_time,
                    row_sample=S, row_index=Kall, options=opts, signals=tuple(signals))


def _saturated_rows(trajs: Sequence[Trajectory], settings: Sequence[FilterSettings], E: np.ndarray, J: np.ndarray,
                    S: np.ndarray, opts: AssemblyOptions) -> np.ndarray:
    """Rows to remove with ``drop_saturated``: row r (experiment E, joint J, full-rate sample S) when more than
    ``slow_weight_tol`` of its decimation filter's absolute weights fall on saturated samples of ``tau_J`` (of any
    joint's torque with ``saturated_all_joints``)."""
    drop = np.zeros(E.size, bool)
    for ex, (traj, st) in enumerate(zip(trajs, settings)):
        sat = saturation_mask(traj.tau, opts.tau_limits)
        if not sat.any():
            continue
        h = np.ones(1)
        if st.n_d > 1:
            h = np.abs(decimation_filter(st.n_d, ftype="fir", cutoff_ratio=st.cutoff_ratio))
            h = h / h.sum()
        bad = np.zeros(sat.shape, bool)
        for j in np.flatnonzero(sat.any(axis=0)):
            expo = np.convolve(sat[:, j].astype(float), h)[(h.size - 1) // 2:][:traj.n_samples]
            bad[:, j] = expo > opts.slow_weight_tol
        if opts.saturated_all_joints:
            bad[:] = bad.any(axis=1, keepdims=True)
        m = ex == E
        drop[m] = bad[S[m], J[m]]
    return drop


def merge_metric_basis(assemblies: Iterable[Any]) -> dict[str, Any]:
    """One ``rel_err_basis`` for several assemblies (anything with :meth:`Assembly.metric_basis`: cut-offs
    and decimation factors of every experiment, rows and samples summed)."""
    parts = [a.metric_basis() for a in assemblies]
    if not parts:
        return {}
    out = dict(parts[0])
    for p in parts[1:]:
        out["cutoff_hz"] = out["cutoff_hz"] + p["cutoff_hz"]
        out["n_d"] = out["n_d"] + p["n_d"]
        out["rows"] += p["rows"]
        out["samples"] += p["samples"]
    return out


def basis_text(basis: Mapping[str, Any] | None) -> str:
    """``"filtered, decimated system (cut-off 21.5 Hz, n_d = 10)"`` from a ``rel_err_basis``."""
    if not basis:
        return "filtered, decimated system"
    cut = sorted({round(float(c), 4) for c in basis.get("cutoff_hz", ())})
    nd = sorted({int(x) for x in basis.get("n_d", ())})
    txt = (f"filtered, decimated system (Butterworth cut-off {', '.join(f'{c:.4g}' for c in cut)} Hz, "
           f"n_d = {', '.join(str(x) for x in nd)}, {basis.get('rows', '?')} rows of all joints")
    if basis.get("min_velocity") is not None:
        txt += f", rows slower than {basis['min_velocity']} rad/s removed"
    return txt + ")"
