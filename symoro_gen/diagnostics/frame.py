"""Observation systems with the signals behind each row, for residual analysis and extra columns.

:func:`build_frame` runs the assembly stage (:func:`symoro_gen.observations.assemble`, Gautier's
band-pass filtering and parallel decimation, RX-90 paper eq. 14-16) and builds the :class:`Frame`
from the :class:`~symoro_gen.observations.Assembly` it returns (:func:`frame_from_assembly`): the
full-rate band-pass ``q, dq, ddq`` of every experiment, the decimated measured torques of all joints
and the sample behind every row all come from the assembly; nothing is filtered a second time.
:func:`attach_model_torque` adds the torque transmitted according to a fitted model,
``tau_hat = IDM(q, dq, ddq) chi`` low-passed by a zero-phase Butterworth, and its derivatives
``dtau_hat, ddtau_hat``: candidate columns that depend on the torque use it rather than the measured
torque, whose noise is the noise of ``Y`` and would correlate with it (errors-in-variables: a column
holding the measurement noise of ``Y`` "explains" that noise). Candidate effects are functions of
these signals; their columns are evaluated at full rate and decimated in parallel with the same
FIR/IIR filter as ``W`` and ``Y`` (RX-90 paper eq. 15), so ``Y = [W X] [chi; beta]`` keeps holding
after decimation.

Memory: the frame holds the decimated system and row signals, and the full-rate band-pass ``q, dq, ddq``
(and model torque) of every experiment, which the candidates read whole (rest segments, friction laws,
composed signals). Every decimation of full-rate columns goes by bounded stretches of samples
(:meth:`Experiment.decimate_stretches`: the FIR window of each stretch, the same numbers as one pass), and
the callbacks of :meth:`Frame.full_rate_columns_batched` see at most ``FULL_RATE_CALL_SAMPLES`` samples per
call, so no transient copy of all columns at every sample is made on top of those signals.

Rows are grouped per joint as in the assembly: all rows of joint 1 (experiment after experiment),
then joint 2...
"""
from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy import signal

from ..errors import IdentificationError
from ..model import IdentificationModel
from ..observations.assembly import Assembly, ExperimentSignals, assemble
from ..observations.options import AssemblyOptions
from ..observations.raw import full_rate_torque
from ..observations.system import ObservationSystem
from ..preprocessing.filtering import (
    FilterSettings,
    decimate,
    decimation_filter,
    estimate_dynamics_bandwidth,
    filter_and_differentiate,
    fir_buffer_length,
    fir_decimate,
    fir_decimate_padded,
    fir_group_size,
)
from ..preprocessing.trajectory import Trajectory


@functools.lru_cache(maxsize=32)
def _fir_taps(n_d: int, cutoff_ratio: float) -> np.ndarray:
    h = decimation_filter(n_d, ftype="fir", cutoff_ratio=cutoff_ratio)
    h.setflags(write=False)
    return h


#: bytes of the full-rate columns of one stretch of samples (:meth:`Frame.full_rate_columns_batched`)
FULL_RATE_BATCH_BYTES = 16 * 2 ** 20
#: most full-rate samples per call of the callback of :meth:`Frame.full_rate_columns_batched`: its own work
#: arrays are bounded too, not only the columns it returns (the emitted geometry derivative of a 7-joint arm
#: holds ~2,000 products per sample and joint before contracting them with the parameters: ~30 MB here)
FULL_RATE_CALL_SAMPLES = 256

__all__ = ["Experiment", "Frame", "build_frame", "frame_from_assembly", "attach_model_torque", "model_torque",
           "split_holdout", "common_bandwidth", "noise_gains", "T_ORIGIN_KEY"]

#: ``Trajectory.meta`` key holding the time origin [s] of the original recording (kept by hold-out splits)
T_ORIGIN_KEY = "diagnose_t_origin"

SIGNALS = ("q", "dq", "ddq", "tau")
MODEL_SIGNALS = ("tau_hat", "dtau_hat", "ddtau_hat")
#: the model torque of the candidates is low-passed at this many times the dynamics bandwidth
MODEL_TORQUE_BANDWIDTH_FACTOR = 2.5


@dataclass(frozen=True, eq=False)
class Experiment:
    """Full-rate signals of one experiment, edge samples dropped.

    Attributes
    ----------
    source : str
    loaded : bool
    settings : FilterSettings
        Those the assembly used.
    t : ndarray, shape (M,)
        Time since the start of the original recording [s].
    q, dq, ddq : ndarray, shape (M, n)
        Band-pass estimates from the measured positions [rad, rad/s, rad/s^2 (m...)].
    tau : ndarray, shape (M, n)
        Measured torques [N m].
    tau_hat, dtau_hat, ddtau_hat : ndarray, shape (M, n), or None
        Model torque low-passed by the position Butterworth, and its derivatives [N m, N m/s, N m/s^2]
        (None until :func:`attach_model_torque`).
    n_rows : int
        Decimated rows of this experiment (per joint).
    q_noise, dq_noise : ndarray, shape (n,)
        Estimated standard deviations of the white noise on the measured positions and of what is
        left of it in the band-pass velocity (from the part of ``q`` above the cut-off).
    """

    source: str
    loaded: bool
    settings: FilterSettings
    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    tau: np.ndarray
    n_rows: int
    q_noise: np.ndarray
    dq_noise: np.ndarray
    tau_hat: np.ndarray | None = None
    dtau_hat: np.ndarray | None = None
    ddtau_hat: np.ndarray | None = None

    @property
    def n_samples(self) -> int:
        return self.t.shape[0]

    def decimate(self, x: np.ndarray) -> np.ndarray:
        """Parallel decimation of full-rate columns ``x`` (M, ...) with this experiment's filter
        (:func:`symoro_gen.preprocessing.filtering.decimate`, FIR taps cached)."""
        st = self.settings
        x = np.asarray(x, float)
        if st.ftype == "fir" and st.n_d > 1 and x.ndim == 2:
            return fir_decimate(np.ascontiguousarray(x), _fir_taps(st.n_d, st.cutoff_ratio), st.n_d)
        return decimate(x, st.n_d, ftype=st.ftype, cutoff_ratio=st.cutoff_ratio, source=self.source)

    def decimate_stretches(self, fill: Callable[[np.ndarray, int, int], None], width: int, *,
                           batch_bytes: int = FULL_RATE_BATCH_BYTES) -> np.ndarray:
        """:meth:`decimate` of ``width`` full-rate columns that ``fill(dst, a, b)`` writes for samples ``a:b``
        into ``dst`` (b - a, width), without the full-rate array of the whole experiment.

        The FIR decimation (:func:`symoro_gen.preprocessing.filtering.fir_decimate`) is a sum over a window
        of ``L`` full-rate samples per kept sample (RX-90 paper sec. 4, parallel decimation), so the kept
        samples of a stretch need the columns of that stretch and of ``L - 1`` samples around it only: the
        stretches' zero-padded buffers (at most ``batch_bytes`` each, at least the filter window) go through
        the same grouped products as the whole array, and the outputs are the same numbers. ``fill`` writes every
        entry of ``dst`` (only the buffer's padding is zeroed). Without a FIR
        decimation (``ftype="iir"``, ``n_d = 1``) the whole array is built and decimated."""
        st = self.settings
        N = self.n_samples
        if not (st.ftype == "fir" and st.n_d > 1):
            full = np.empty((N, width))
            fill(full, 0, N)
            return self.decimate(full)
        h = _fir_taps(st.n_d, st.cutoff_ratio)
        n_d, L = st.n_d, h.size
        half, group = (L - 1) // 2, fir_group_size(st.n_d)
        n_out = -(-N // n_d)
        # outputs per stretch: a multiple of the FIR group, with its samples within batch_bytes
        per = max(group, (max(batch_bytes // (8 * max(width, 1)), L) // n_d) // group * group)
        dec = np.empty((n_out, width))
        for k0 in range(0, n_out, per):
            k1 = min(n_out, k0 + per)
            rows = fir_buffer_length(k1 - k0, n_d, L, group)
            lo = k0 * n_d - half                # sample of the first buffer row
            a, b = max(lo, 0), min(lo + rows, N)
            buf = np.empty((rows, width))   # zero padding outside the samples only: fill writes every other row
            if b > a:
                buf[:a - lo] = 0.0
                buf[b - lo:] = 0.0
                fill(buf[a - lo:b - lo], a, b)
            else:
                buf[:] = 0.0
            dec[k0:k1] = fir_decimate_padded(buf, h, n_d, k1 - k0, group)
        return dec


@dataclass(frozen=True, eq=False)
class Frame:
    """An observation system with, for each row, the signals of its sample.

    Attributes
    ----------
    system : ObservationSystem
        ``W`` (r, c) of the declared model (base + payload columns), ``Y`` (r,), ``joint`` (r,).
    experiments : tuple of Experiment
    row_experiment : ndarray of int, shape (r,)
    row_index : ndarray of int, shape (r,)
        Index of the row's sample among the decimated samples of its experiment.
    sig : dict of str -> ndarray, shape (r, n)
        Decimated signals of *all* joints at each row's sample: ``q dq ddq tau`` (and ``tau_hat
        dtau_hat ddtau_hat`` once attached);
        ``t`` (r,) is the time since the start of the recording [s].
    assembly : Assembly or None
        The assembly the frame was built from (full-rate signals, provenance, options).
    """

    system: ObservationSystem
    experiments: tuple[Experiment, ...]
    row_experiment: np.ndarray
    row_index: np.ndarray
    sig: Mapping[str, np.ndarray]
    assembly: Assembly | None = None

    @property
    def n_rows(self) -> int:
        return self.system.Y.size

    @property
    def n_joints(self) -> int:
        return self.experiments[0].q.shape[1]

    @property
    def joint(self) -> np.ndarray:
        return self.system.joint

    def rows_of(self, j: int) -> np.ndarray:
        return np.flatnonzero(self.system.joint == j)

    def full_rate_columns(self, fn: Callable[[Experiment], Mapping[int, np.ndarray]], p: int) -> np.ndarray:
        """Columns evaluated at full rate and decimated in parallel.

        Parameters
        ----------
        fn : callable
            ``fn(experiment) -> {joint: array (M, p)}``: the columns on the rows of each joint
            (joints not in the mapping get zeros).
        p : int
            Number of columns.

        Returns
        -------
        ndarray, shape (r, p)
        """
        X = np.zeros((self.n_rows, p))
        for e, ex in enumerate(self.experiments):
            parts = fn(ex)
            if not parts:
                continue
            keys = sorted(parts)
            cols = [np.asarray(parts[j], float).reshape(ex.n_samples, p) for j in keys]
            dec = ex.decimate_stretches(functools.partial(_copy_columns, cols), len(keys) * p)
            for i, j in enumerate(keys):
                m = (self.row_experiment == e) & (self.system.joint == j)
                X[m] = dec[self.row_index[m], i * p:(i + 1) * p]
        return X

    def full_rate_columns_batched(self, fn: Callable[[Experiment, int, int], np.ndarray], p: int, *,
                                  batch_bytes: int = FULL_RATE_BATCH_BYTES,
                                  call_samples: int = FULL_RATE_CALL_SAMPLES) -> np.ndarray:
        """:meth:`full_rate_columns` of columns on the rows of *every* joint, evaluated at full rate over
        bounded stretches of samples instead of the whole recording.

        The FIR decimation (:func:`symoro_gen.preprocessing.filtering.fir_decimate`) is a sum over a window
        of ``L`` full-rate samples per kept sample (RX-90 paper sec. 4, parallel decimation), so the kept
        samples of a stretch need the full-rate columns of that stretch and of ``L - 1`` samples around it
        only: the result equals :meth:`full_rate_columns` to rounding while the full-rate array (``n p``
        columns at every sample, e.g. the regressor's tangent) never exists whole.

        Parameters
        ----------
        fn : callable
            ``fn(experiment, a, b) -> array (b - a, n, p)``: the columns of samples ``a:b`` on each
            joint's rows.
        p : int
            Number of columns.
        batch_bytes : int
            Size of the full-rate array of one stretch (at least the filter window).
        call_samples : int
            Most samples per call of ``fn`` (a stretch is filled by consecutive calls): bounds the memory
            ``fn`` itself uses, which the size of what it returns does not tell. ``fn`` is a function of each
            sample's signals, so the columns do not depend on how the samples are split.

        Returns
        -------
        ndarray, shape (r, p)
        """
        X = np.zeros((self.n_rows, p))
        for e, ex in enumerate(self.experiments):
            n = ex.q.shape[1]

            def fill(dst: np.ndarray, a: int, b: int, ex: Experiment = ex) -> None:
                _fill_columns(dst, fn, ex, a, b, call_samples)

            self._scatter(X, e, ex.decimate_stretches(fill, n * p, batch_bytes=batch_bytes), n, p)
        return X

    def _scatter(self, X: np.ndarray, e: int, dec: np.ndarray, n: int, p: int) -> None:
        """Rows of experiment ``e`` of every joint ``j`` from the decimated columns ``dec[:, j p:(j + 1) p]``."""
        for j in range(n):
            m = (self.row_experiment == e) & (self.system.joint == j)
            X[m] = dec[self.row_index[m], j * p:(j + 1) * p]

    def row_columns(self, fn: Callable[[int, np.ndarray], np.ndarray], p: int) -> np.ndarray:
        """Columns computed from the decimated row signals: ``fn(j, rows) -> (len(rows), p)`` per joint."""
        X = np.zeros((self.n_rows, p))
        for j in range(self.n_joints):
            rows = self.rows_of(j)
            if rows.size:
                X[rows] = np.asarray(fn(j, rows), float).reshape(rows.size, p)
        return X

    def signal_arrays(self) -> tuple[np.ndarray, ...]:
        """The arrays the frame's rows and full-rate signals are (row experiment, row index, joint, and each
        experiment's ``t q dq ddq``): caches of columns that are functions of these alone key on their
        identities (and hold them, so that an identity is not reused)."""
        arrs = [self.row_experiment, self.row_index, self.system.joint]
        for ex in self.experiments:
            arrs += [ex.t, ex.q, ex.dq, ex.ddq]
        return tuple(arrs)

    def samples(self) -> dict[str, np.ndarray]:
        """Decimated signals per sample (one entry per decimated sample, not per row):
        arrays (s, n) and ``t`` (s,), plus ``experiment`` (s,) - rows of joint 0 define the samples."""
        rows = self.rows_of(0)
        out = {k: v[rows] for k, v in self.sig.items()}
        out["experiment"] = self.row_experiment[rows]
        return out


def _fill_columns(dst: np.ndarray, fn: Callable[[Experiment, int, int], np.ndarray], ex: Experiment, a: int, b: int,
                  call_samples: int) -> None:
    """``dst`` (b - a, n p) from ``fn(ex, a2, b2)`` over consecutive ranges of at most ``call_samples`` samples."""
    step = max(1, int(call_samples))
    for a2 in range(a, b, step):
        b2 = min(b, a2 + step)
        dst[a2 - a:b2 - a] = np.asarray(fn(ex, a2, b2), float).reshape(b2 - a2, dst.shape[1])


def _copy_columns(arrays: Sequence[np.ndarray], dst: np.ndarray, a: int, b: int) -> None:
    """Samples ``a:b`` of the full-rate ``arrays`` side by side into ``dst`` (a fill of
    :meth:`Experiment.decimate_stretches`)."""
    c = 0
    for x in arrays:
        w = x.shape[1]
        dst[:, c:c + w] = x[a:b]
        c += w


def common_bandwidth(trajectories: Sequence[Trajectory], **kw) -> float:
    """The largest estimated dynamics bandwidth ``f_dyn`` of the experiments [Hz] (one filter rule for all)."""
    return max(estimate_dynamics_bandwidth(tr.q, 1.0 / tr.dt, **kw) for tr in trajectories)


def split_holdout(trajectories: Sequence[Trajectory], fraction: float) -> tuple[list[Trajectory], list[Trajectory]]:
    """Split each experiment in a leading part (identification) and a contiguous trailing part
    (validation) holding ``fraction`` of its samples. Both keep the time origin of the recording."""
    if not 0.0 < fraction < 1.0:
        raise ValueError(f"holdout fraction must lie in (0, 1), got {fraction!r}")
    ident: list[Trajectory] = []
    valid: list[Trajectory] = []
    for tr in trajectories:
        N = tr.n_samples
        k = int(round(N * (1.0 - fraction)))
        t0 = float(tr.meta.get(T_ORIGIN_KEY, tr.t[0]))
        for a, b, out in ((0, k, ident), (k, N, valid)):
            meta = dict(tr.meta)
            meta[T_ORIGIN_KEY] = t0
            out.append(Trajectory(t=tr.t[a:b], q=tr.q[a:b], tau=tr.tau[a:b],
                                  dq=None if tr.dq is None else tr.dq[a:b],
                                  ddq=None if tr.ddq is None else tr.ddq[a:b],
                                  source=f"{tr.source}[rows {a + 1}-{b}]", loaded=tr.loaded, meta=meta))
    return ident, valid


def _row_signals(exps, keys, row_exp, row_idx, n) -> dict:
    """Decimated signals ``keys`` of every experiment as one (r, n) array per signal (all joints per row)."""
    r = row_exp.size
    sig = {k: np.zeros((r, n)) for k in keys}
    for e, ex in enumerate(exps):
        dec = ex.decimate_stretches(functools.partial(_copy_columns, [getattr(ex, k) for k in keys]), n * len(keys))
        if dec.shape[0] != ex.n_rows:
            raise IdentificationError(f"{ex.source}: {dec.shape[0]} decimated samples, the assembler kept "
                                      f"{ex.n_rows} rows per joint: cannot line the signals up")
        m = row_exp == e
        for i, k in enumerate(keys):
            sig[k][m] = dec[row_idx[m], i * n:(i + 1) * n]
    return sig


#: ``IDM(q, dq, ddq) chi`` at every sample (:func:`symoro_gen.observations.full_rate_torque`)
model_torque = full_rate_torque


def attach_model_torque(frame: Frame, model: IdentificationModel, theta: Mapping[str, float]) -> Frame:
    """A copy of ``frame`` with the model torque ``tau_hat`` (and derivatives) of parameters ``theta``.

    ``tau_hat`` is computed at full rate from the band-pass kinematics, then low-passed by a zero-phase
    Butterworth at ``MODEL_TORQUE_BANDWIDTH_FACTOR`` times the dynamics bandwidth (at most the position
    cut-off) and differentiated like the positions. The band-pass acceleration carries the position
    noise amplified by ``(2 pi f)^2`` up to the decimation cut-off; a model torque built from it would
    carry that noise, which is (minus) the noise the residual gets from ``W``: columns made of it would
    correlate with the residual (errors in variables). Below ``2.5 f_dyn`` little of it is left while the
    torque of the motion (below ``f_dyn``) passes unchanged (gain > 0.998)."""
    exps = []
    for ex in frame.experiments:
        st = ex.settings
        th = model_torque(model, theta, ex.q, ex.dq, ex.ddq, ex.loaded)
        fc = min(st.cutoff_hz, MODEL_TORQUE_BANDWIDTH_FACTOR * st.dynamics_bandwidth_hz)
        tf, d1, d2 = filter_and_differentiate(th, st.fs, fc, st.order, source=ex.source)
        exps.append(replace(ex, tau_hat=tf, dtau_hat=d1, ddtau_hat=d2))
    sig = dict(frame.sig)
    sig.update(_row_signals(exps, MODEL_SIGNALS, frame.row_experiment, frame.row_index, frame.n_joints))
    return replace(frame, experiments=tuple(exps), sig=sig)


def noise_gains(fs: float, cutoff_hz: float, order: int = 4, n_freq: int = 4096) -> tuple[float, float]:
    """For white noise on ``q``: std of ``q - lowpass(q)`` and of the band-pass velocity, per unit std.

    Computed from the frequency responses (zero-phase Butterworth ``|H|^2``; central difference
    ``sin(w)/dt``), averaged over [0, fs/2] where white noise spreads its variance evenly."""
    sos = signal.butter(order, cutoff_hz, fs=fs, output="sos")
    f = np.linspace(0.0, fs / 2.0, n_freq)
    _, h = signal.sosfreqz(sos, worN=f, fs=fs)
    H2 = np.abs(h) ** 2
    hp = math.sqrt(float(np.mean((1.0 - H2) ** 2)))
    dv = math.sqrt(float(np.mean((H2 * np.sin(2 * math.pi * f / fs) * fs) ** 2)))
    return hp, dv


def _experiment(sg: ExperimentSignals, t_origin: float) -> Experiment:
    """The frame's view of one experiment of the assembly: its full-rate signals, and the position noise
    estimated from what the Butterworth removed (``q_raw - q``)."""
    st = sg.settings
    hp, dv = noise_gains(st.fs, st.cutoff_hz, st.order)
    q_noise = np.std(sg.q_raw - sg.q, axis=0) / max(hp, 1e-12)
    return Experiment(source=sg.source, loaded=sg.loaded, settings=st, t=sg.t - t_origin, q=sg.q, dq=sg.dq,
                      ddq=sg.ddq, tau=sg.tau_raw, n_rows=int(sg.tau_rows.shape[0]), q_noise=q_noise,
                      dq_noise=q_noise * dv)


def frame_from_assembly(asm: Assembly, t_origins: Sequence[float] | None = None) -> Frame:
    """The :class:`Frame` of an :class:`~symoro_gen.observations.Assembly` built with ``keep_signals``.

    Parameters
    ----------
    asm : Assembly
        Every joint must have a row on every decimated sample (no ``min_velocity`` removal).
    t_origins : sequence of float, optional
        Time origin of each experiment's original recording (``Experiment.t`` and ``sig["t"]`` are
        counted from it); default the first recorded time of each experiment.

    Returns
    -------
    Frame
        ``sig["tau"]`` holds the assembly's decimated measured torques (``Y`` of each row is
        ``sig["tau"][row, joint]``); ``q, dq, ddq`` are the assembly's full-rate signals decimated
        with the same filter.
    """
    if not asm.signals:
        raise IdentificationError("the assembly kept no signals (AssemblyOptions.keep_signals=False): "
                                  "cannot build a diagnosis frame from it")
    for rep in asm.experiments:
        if len(set(rep.rows_per_joint)) != 1:
            raise IdentificationError(f"{rep.source}: rows per joint differ {rep.rows_per_joint}; "
                                      "diagnose needs every joint on every sample (no min_velocity removal)")
    if t_origins is None:
        t_origins = [float(sg.t[0]) - sg.first / sg.settings.fs for sg in asm.signals]
    exps = tuple(_experiment(sg, float(t0)) for sg, t0 in zip(asm.signals, t_origins))
    sysm = asm.system
    n = exps[0].q.shape[1]
    row_exp = np.asarray(asm.row_experiment, int)
    row_idx = np.asarray(asm.row_index, int)
    sig = _row_signals(exps, SIGNALS[:3], row_exp, row_idx, n)
    tau = np.zeros((row_exp.size, n))
    tt = np.zeros(row_exp.size)
    for e, sg in enumerate(asm.signals):
        m = row_exp == e
        tau[m] = sg.tau_rows[row_idx[m]]
        tt[m] = asm.row_time[m] - float(t_origins[e])
    sig["tau"] = tau
    sig["t"] = tt
    return Frame(system=sysm, experiments=exps, row_experiment=row_exp, row_index=row_idx, sig=sig, assembly=asm)


def build_frame(model: IdentificationModel, trajectories: Sequence[Trajectory], *,
                dynamics_bandwidth_hz: float | None = None, payload_columns: bool | None = None,
                **filter_kw) -> Frame:
    """Assemble ``Y = W chi`` (:func:`symoro_gen.observations.assemble`) and attach the signals of each row.

    Parameters
    ----------
    model : IdentificationModel
        Generated-model interface (``N_JOINTS``, ``BASE_NAMES``, ``regressor``...).
    trajectories : sequence of Trajectory
    dynamics_bandwidth_hz : float, optional
        ``f_dyn`` for the filter rules (same for every experiment); default: estimated per experiment.
    payload_columns : bool, optional
        Default: True when an experiment is loaded and the model has payload columns.
    **filter_kw
        ``cutoff_hz``, ``n_d``, ``order``, ``ftype``... (fields of :class:`~symoro_gen.observations.AssemblyOptions`).

    Returns
    -------
    Frame
    """
    trajs = list(trajectories)
    if not trajs:
        raise ValueError("no trajectory given")
    if payload_columns is None:
        payload_columns = any(tr.loaded for tr in trajs) and bool(tuple(getattr(model, "PAYLOAD_NAMES", ())))
    opts = AssemblyOptions.from_keywords(dynamics_bandwidth_hz=dynamics_bandwidth_hz,
                                         payload_columns=payload_columns, keep_signals=True, **filter_kw)
    asm = assemble(model, trajs, opts)
    t0 = [float(tr.meta.get(T_ORIGIN_KEY, tr.t[0])) for tr in trajs]
    return frame_from_assembly(asm, t0)
