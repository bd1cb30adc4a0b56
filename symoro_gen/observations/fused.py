"""The assembly engine: the decimated rows of the observation system, streaming (RX-90 paper eq. 14-16).

Gautier's parallel decimation (M. Gautier & S. Briot, the RX-90 paper, eq. 14-16; [GB-gains] in
``docs/references.md``): zero-phase Butterworth of ``q``, central differences, the base regressor, then the
same ``20 n_d + 1``-tap Hamming FIR applied to ``Y`` and to every column of ``W``, one sample in ``n_d`` kept,
zero padding beyond the ends as ``resample_poly``. :func:`decimated_rows` yields those rows block after
block in a compact form (the distinct columns of ``W``, then the torques of every joint) and is the one
producer of them: :func:`~symoro_gen.observations.assemble` and :func:`~symoro_gen.observations.iter_chunks`
expand them into :class:`~symoro_gen.observations.ObservationSystem` rows (``identify``, ``diagnose``), the
fleet folds them into per-joint QR factors (:mod:`symoro_gen.fleet.fused`) without ever building ``W``.
It is the same computation as a plain blocked FIR, only cheaper:

* **polyphase FIR with state across blocks**: the samples are taken ``n_d`` at a time ("super-rows",
  ``X_s``, shape ``(n_d, C)``); with the taps cut in 21 phases ``H[p, r] = h[p n_d + r]``, output ``k``
  is ``y_k = sum_p (H X_{k+p})[p]``. One matrix product ``H (21 x n_d) @ [X_s ...]`` per batch of
  super-rows (one BLAS call over the batch, 42 flops per sample and column: the floor of a
  ``20 n_d + 1``-tap FIR is 40), and the 20 partial outputs that straddle a batch border are carried to
  the next batch, so no sample is evaluated or filtered twice;
* **only the distinct columns**: the structurally non-zero entries of ``W`` (per joint row) that are
  equal up to a constant factor for random states are equal for all states (analytic functions);
  only one of each is filtered (:class:`ColumnMap`), then scaled back after decimation (80x fewer rows);
* **in cache**: the regressor is evaluated ``REGRESSOR_ROWS`` samples at a time into a reused buffer, and
  its distinct columns copied straight into the layout of the matrix product (``BATCH_SUPER_ROWS``
  super-rows per product) by a compiled row gather (:data:`_KERNELS_SOURCE`; ``np.take`` without a C
  compiler, same numbers); the generated C regressor is called by address (:func:`_raw_regressor`,
  without ``model.regressor``'s per-call checks); the products fill a window of ``RING_SUPER_ROWS``
  super-rows whose outputs are summed by a compiled row-by-row loop (21 vector adds without a compiler,
  same order of additions, same numbers), its last 20 products carried to the front when it is full;
* **the filters' rule** (``f_dyn`` when the cut-off or ``n_d`` is not given): :func:`dynamics_bandwidth`,
  ``estimate_dynamics_bandwidth``'s Welch periodogram with each segment's mean and line from sums per
  half-segment (same ``f_dyn``); the central differences of ``q`` are one compiled pass (same numbers),
  the Butterworth sections run on the channels together (compiled; SciPy's numbers).

The Butterworth filter of ``q`` is zero-phase (forward-backward), so it is applied per outer block of
samples (``AssemblyOptions.chunk_samples``, else ``max_chunk_mb`` or 64k samples) with a settling margin at
both ends: rows equal those of one pass over the whole experiment to ~1e-10 relative at the block borders
(the truncated transient), exactly elsewhere. What the engine does not cover (:func:`fused_applies`:
``ftype="iir"``, ``n_d = 1``, ``min_velocity``, the payload columns of a loaded experiment, recorded
derivatives, experiments too short to filter) the assembly computes by its blocked FIR
(:mod:`symoro_gen.observations.assembly`).
"""
from __future__ import annotations

import ctypes
import hashlib
import math
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy import signal

from ..atomic import write_text_atomic
from ..errors import ShapeError
from ..model import IdentificationModel
from ..preprocessing.filtering import (
    PAD_PERIODS,
    FilterSettings,
    bandwidth_from_power,
    blas_threads,
    butterworth_settle_samples,
    choose_filter_settings,
    decimation_filter,
    differentiate,
    estimate_dynamics_bandwidth,
    lowpass_positions,
    min_filter_samples,
    still_note,
)
from ..preprocessing.motion import noise_level_joints
from ..preprocessing.trajectory import Trajectory
from ..runtime import GeneratedModel
from ..runtime.ccompile import build_library, user_cache
from .options import AssemblyOptions

__all__ = ["BATCH_SUPER_ROWS", "OUTER_SAMPLES", "REGRESSOR_ROWS", "WELCH_SEGMENT", "ColumnMap", "column_map",
           "compiled_helpers", "decimated_rows", "dynamics_bandwidth", "filter_settings", "fused_applies",
           "model_column_map", "outer_super_rows", "zero_phase_kinematics"]

#: super-rows (``n_d`` samples each) per matrix product: the batch's inputs (16 x 80 x 208 doubles at
#: n_d = 80, 2 MB) and products stay in the L2/L3 caches
BATCH_SUPER_ROWS = 16
#: samples per regressor call: its output (640 x 7 x 64 doubles, 2.3 MB) is gathered while still cached
REGRESSOR_ROWS = 640
#: super-rows of products kept before the outputs are summed and the window shifted
RING_SUPER_ROWS = 128
#: full-rate samples per Butterworth block (the zero-phase filter's margins are paid once per block)
OUTER_SAMPLES = 65536

_KERNELS_SOURCE = r"""
/* symoro_gen.observations.fused: copy the distinct columns of regressor rows (row i of W, stride ldw) to
   row i of X (stride ldx): X[i, u] = W[i, src[u]]. */
void symoro_gather_rows(long m, const double *W, long ldw, const long *src, long U, double *X, long ldx)
{
    for (long i = 0; i < m; i++) {
        const double *w = W + i * ldw;
        double *x = X + i * ldx;
        for (long u = 0; u < U; u++)
            x[u] = w[src[u]];
    }
}

/* The polyphase outputs of a window: y[i, c] = sum_p Z[i + p, p, c] for i < k (Z: rows of P x C), summed
   in the order p = 0, 1, ..., P - 1 (NumPy's sequence of vector adds: the same numbers). */
void symoro_diagonal_sum(long k, long P, long C, const double *Z, double *y)
{
    for (long i = 0; i < k; i++) {
        double *out = y + i * C;
        const double *z0 = Z + i * P * C;
        for (long c = 0; c < C; c++)
            out[c] = z0[c];
        for (long p = 1; p < P; p++) {
            const double *z = Z + ((i + p) * P + p) * C;
            for (long c = 0; c < C; c++)
                out[c] += z[c];
        }
    }
}

/* Decimated rows into a joint's Fortran-ordered QR buffer: dst[u * ld + i] = y[i * C + src[u]] * scale[u]
   for the k rows i and the L columns u of the joint (one multiply: the numbers of NumPy's indexed copy). */
void symoro_scatter_scaled(long k, const double *y, long C, long L, const long *src, const double *scale,
                           double *dst, long ld)
{
    for (long u = 0; u < L; u++) {
        const double *col = y + src[u];
        const double s = scale[u];
        double *d = dst + u * ld;
        for (long i = 0; i < k; i++)
            d[i] = col[i * C] * s;
    }
}

/* One Welch segment of the filters' rule: buf[c, k] = ((x[k, c] - mean[c]) - slope[c] tc[k]) w[k] for the m
   rows k of x (nch channels, C order) into buf (nch x m): NumPy's subtract, multiply, subtract and
   multiply in one pass (same operations, same numbers). */
__attribute__((optimize("fp-contract=off")))
void symoro_detrend_window(long m, long nch, const double *x, const double *mean, const double *slope,
                           const double *tc, const double *w, double *buf)
{
    for (long c = 0; c < nch; c++) {
        double *b = buf + c * m;
        const double mu = mean[c], sl = slope[c];
        for (long k = 0; k < m; k++)
            b[k] = ((x[k * nch + c] - mu) - sl * tc[k]) * w[k];
    }
}

/* Periodogram accumulation: P[i] += re_i * re_i + im_i * im_i over the n complex values X (interleaved). */
__attribute__((optimize("fp-contract=off")))
void symoro_add_power(long n, const double *X, double *P)
{
    for (long i = 0; i < n; i++) {
        const double re = X[2 * i], im = X[2 * i + 1];
        P[i] += re * re + im * im;
    }
}

/* Central differences along axis 0 of x (n rows, nch channels, C order), one pass for both derivatives:
   d1 as numpy.gradient (interior (x[k+1] - x[k-1]) / (2 dt), one-sided first order at the ends), d2 as
   symoro_gen.preprocessing.filtering.differentiate(second=True) (interior (x[k+1] - 2 x[k] + x[k-1]) / dt^2,
   the ends copied from their neighbours); no contracted multiply-adds: the same numbers. */
__attribute__((optimize("fp-contract=off")))
void symoro_central_differences(long n, long nch, const double *x, double dt, double *d1, double *d2)
{
    const double h2 = 2.0 * dt, dd = dt * dt;
    for (long k = 1; k < n - 1; k++) {
        const double *a = x + (k - 1) * nch, *b = x + k * nch, *c = x + (k + 1) * nch;
        double *o1 = d1 + k * nch, *o2 = d2 + k * nch;
        for (long j = 0; j < nch; j++) {
            o1[j] = (c[j] - a[j]) / h2;
            o2[j] = (c[j] - 2.0 * b[j] + a[j]) / dd;
        }
    }
    for (long j = 0; j < nch; j++) {
        d1[j] = (x[nch + j] - x[j]) / dt;
        d1[(n - 1) * nch + j] = (x[(n - 1) * nch + j] - x[(n - 2) * nch + j]) / dt;
        d2[j] = d2[nch + j];
        d2[(n - 1) * nch + j] = d2[(n - 2) * nch + j];
    }
}

/* Second-order sections along axis 0 of x (n rows, nch channels, C order), in place, forward or
   (reverse != 0) backward, state zi (nch x nsec x 2) updated: the recursion of scipy.signal.sosfilt
   (direct form II transposed) with the channels advanced together, without contracted multiply-adds so
   that the numbers are SciPy's. */
__attribute__((optimize("fp-contract=off")))
void symoro_sosfilt_rows(long n, long nch, long nsec, const double *sos, double *x, double *zi, int reverse)
{
    for (long k = 0; k < n; k++) {
        double *row = x + (reverse ? n - 1 - k : k) * nch;
        for (long c = 0; c < nch; c++) {
            double xc = row[c];
            double *z = zi + c * nsec * 2;
            for (long s = 0; s < nsec; s++) {
                const double *f = sos + 6 * s;
                double xn = f[0] * xc + z[2 * s];
                z[2 * s] = f[1] * xc - f[4] * xn + z[2 * s + 1];
                z[2 * s + 1] = f[2] * xc - f[5] * xn;
                xc = xn;
            }
            row[c] = xc;
        }
    }
}
"""
_KERNELS: list[dict[str, Callable[..., Any]] | None] = []
_KERNELS_LOCK = threading.Lock()


def compiled_helpers() -> dict[str, Callable[..., Any]] | None:
    """The compiled helpers (:data:`_KERNELS_SOURCE`: the row gather and the multi-channel sections
    filter), built once per machine with the generated models' compiler settings
    (:mod:`symoro_gen.runtime.ccompile`), or None without a C compiler (then ``np.take`` and SciPy's
    ``sosfiltfilt``: the same numbers, slower)."""
    with _KERNELS_LOCK:
        if not _KERNELS:
            fns: dict[str, Callable[..., Any]] | None = None
            try:
                if ctypes.sizeof(ctypes.c_long) != 8:
                    raise OSError("the helpers take 64-bit longs")
                tag = hashlib.sha256(_KERNELS_SOURCE.encode()).hexdigest()[:12]
                c_path = user_cache() / f"engine_kernels_{tag}.c"
                if not c_path.is_file():
                    c_path.parent.mkdir(parents=True, exist_ok=True)
                    write_text_atomic(c_path, _KERNELS_SOURCE)
                lib = ctypes.CDLL(str(build_library(c_path, timeout=60.0).path))
                g, f = lib.symoro_gather_rows, lib.symoro_sosfilt_rows
                d, cd, sc = lib.symoro_diagonal_sum, lib.symoro_central_differences, lib.symoro_scatter_scaled
                L, P = ctypes.c_long, ctypes.c_void_p
                g.restype, g.argtypes = None, [L, P, L, P, L, P, L]
                f.restype, f.argtypes = None, [L, L, L, P, P, P, ctypes.c_int]
                d.restype, d.argtypes = None, [L, L, L, P, P]
                cd.restype, cd.argtypes = None, [L, L, P, ctypes.c_double, P, P]
                sc.restype, sc.argtypes = None, [L, P, L, L, P, P, P, L]
                dw, ap = lib.symoro_detrend_window, lib.symoro_add_power
                dw.restype, dw.argtypes = None, [L, L, P, P, P, P, P, P]
                ap.restype, ap.argtypes = None, [L, P, P]
                fns = {"gather": g, "sosfilt": f, "diagonal_sum": d, "differences": cd, "scatter": sc,
                       "detrend_window": dw, "add_power": ap}
            except Exception:  # noqa: BLE001 - no compiler, read-only cache...: NumPy/SciPy do the same
                fns = None
            _KERNELS.append(fns)
        return _KERNELS[0]


def _zero_phase_rows(q: np.ndarray, fs: float, cutoff_hz: float, order: int, source: str) -> np.ndarray:
    """:func:`~symoro_gen.preprocessing.filtering.lowpass_positions` (zero-phase Butterworth, SciPy's
    ``sosfiltfilt`` with its odd extension and steady-state initial conditions), C-ordered: with the
    compiled sections filter the channels run together and in place (SciPy filters one channel at a
    time, each a chain of dependent multiply-adds)."""
    k = compiled_helpers()
    q = np.ascontiguousarray(q, dtype=float)    # the compiled filter reads C-ordered rows (a CSV's q is not)
    padlen = min(q.shape[0] - 1, int(math.ceil(PAD_PERIODS * fs / cutoff_hz)))
    if k is None or q.ndim != 2 or q.shape[0] < min_filter_samples(order) or padlen < 1:
        return np.ascontiguousarray(lowpass_positions(q, fs, cutoff_hz, order, source=source))
    sos = np.ascontiguousarray(signal.butter(order, cutoff_hz, fs=fs, output="sos"))
    zi = signal.sosfilt_zi(sos)                                   # (nsec, 2)
    ext = np.concatenate([2.0 * q[:1] - q[padlen:0:-1], q, 2.0 * q[-1:] - q[-2:-padlen - 2:-1]])
    n, nch = ext.shape
    for reverse in (0, 1):                                        # forward, then backward on its output
        z = np.ascontiguousarray(zi[None, :, :] * (ext[-1] if reverse else ext[0])[:, None, None])
        k["sosfilt"](n, nch, sos.shape[0], sos.ctypes.data, ext.ctypes.data, z.ctypes.data, reverse)
    return ext[padlen:n - padlen]


#: segment length of the filters' rule on long logs (``estimate_dynamics_bandwidth``'s ``max_segment``)
WELCH_SEGMENT = 2 ** 16


def dynamics_bandwidth(q: np.ndarray, fs: float, *, energy_fraction: float = 0.999, min_bandwidth_hz: float = 1.0,
                       max_segment: int = WELCH_SEGMENT) -> float:
    """:func:`~symoro_gen.preprocessing.filtering.estimate_dynamics_bandwidth` (the filters' rule: the
    frequency below which ``energy_fraction`` of the position energy lies, Welch's average of linearly
    detrended, Hann-windowed, half-overlapping segments on a long log), the same periodogram computed
    cheaper: each segment's mean and least-squares line come from two sums per half-segment, taken for
    the whole log at once by one matrix product (``[1; u] @ blocks``, ``u`` the centred index; segment
    ``i`` is half-blocks ``i`` and ``i + 1``), instead of two strided passes per segment (its mean and
    its product with the time line); the power is accumulated joint-major. Same formula, other summation
    order: periodogram equal to ~1e-13 relative, same ``f_dyn`` (tested on the 1 h log of the benchmark).
    Short logs (one periodogram) go to the original."""
    q = np.asarray(q, float)
    m = int(max_segment)
    if q.ndim != 2 or q.shape[0] <= m or m % 2 or m < 8:
        return estimate_dynamics_bandwidth(q, fs, energy_fraction=energy_fraction, min_bandwidth_hz=min_bandwidth_hz,
                                           max_segment=max_segment)
    N, n = q.shape
    h = m // 2
    nseg = (N - m) // h + 1                     # segments start at 0, h, ... (range(0, N - m + 1, h))
    u = np.arange(h) - (h - 1) / 2.0            # centred index in a half-segment
    S = np.matmul(np.stack([np.ones(h), u]), q[:(nseg + 1) * h].reshape(nseg + 1, h, n))   # (blocks, 2, n)
    S0 = S[:-1, 0] + S[1:, 0]                   # sum of each segment
    # sum (k - (m-1)/2) q_k over a segment: its first half has tc = u - h/2, its second tc = u + h/2
    T = (S[:-1, 1] - (h / 2.0) * S[:-1, 0]) + (S[1:, 1] + (h / 2.0) * S[1:, 0])
    tc = np.arange(m) - (m - 1) / 2.0
    mean, slope = S0 / m, T / (tc @ tc)
    w = np.hanning(m)
    f = np.fft.rfftfreq(m, 1.0 / fs)
    Pj = np.zeros((n, f.size))                  # joint-major: contiguous accumulation
    buf, line = np.empty((n, m)), np.empty((n, m))
    re2, im2 = np.empty((n, f.size)), np.empty((n, f.size))
    kernels = compiled_helpers() if q.flags.c_contiguous else None
    for i in range(nseg):
        if kernels is not None:                  # the same operations in one compiled pass each
            mi, si = np.ascontiguousarray(mean[i]), np.ascontiguousarray(slope[i])
            kernels["detrend_window"](m, n, q[i * h:].ctypes.data, mi.ctypes.data, si.ctypes.data,
                                      tc.ctypes.data, w.ctypes.data, buf.ctypes.data)
            X = np.fft.rfft(buf, axis=1)
            kernels["add_power"](X.size, X.ctypes.data, Pj.ctypes.data)
            continue
        np.subtract(q[i * h:i * h + m].T, mean[i][:, None], out=buf)
        np.multiply(slope[i][:, None], tc, out=line)
        buf -= line
        buf *= w
        X = np.fft.rfft(buf, axis=1)
        np.multiply(X.real, X.real, out=re2)
        np.multiply(X.imag, X.imag, out=im2)
        re2 += im2
        Pj += re2
    return bandwidth_from_power(Pj.T, f, fs, energy_fraction=energy_fraction, min_bandwidth_hz=min_bandwidth_hz,
                                skip=noise_level_joints(q))


def filter_settings(traj: Trajectory, options: AssemblyOptions) -> FilterSettings:
    """The :class:`FilterSettings` of an experiment: Gautier's rules for the values not given
    (:func:`~symoro_gen.preprocessing.filtering.choose_filter_settings`; [G1997] for the cut-off, RX-90 paper
    eq. 14-16 for ``n_d``), with the rule's ``f_dyn`` of a long log from :func:`dynamics_bandwidth` (the same
    value and notes as ``estimate_dynamics_bandwidth``'s, cheaper). The assembly's
    :func:`~symoro_gen.observations.observation_settings`."""
    kw = options.rule_keywords()
    fs = 1.0 / traj.dt
    rule = kw["dynamics_bandwidth_hz"] is None and (kw["cutoff_hz"] is None or kw["n_d"] is None)
    if not rule or traj.n_samples <= WELCH_SEGMENT or traj.q.ndim != 2:
        return choose_filter_settings(fs, traj.q, **kw)
    ef, fmin = kw["rule"].energy_fraction, kw["rule"].min_bandwidth_hz
    f_dyn = dynamics_bandwidth(traj.q, fs, energy_fraction=ef, min_bandwidth_hz=fmin)
    st = choose_filter_settings(fs, None, **{**kw, "dynamics_bandwidth_hz": f_dyn})
    # the note choose_filter_settings writes when it estimates f_dyn itself (tested equal)
    note = f"f_dyn: {100 * ef:g} % of the position energy lies below it (floor {fmin:g} Hz)"
    still = noise_level_joints(traj.q)
    return replace(st, bandwidth_estimated=True, notes=(note, *((still_note(still),) if still else ()), *st.notes))


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


_COLUMN_MAPS: dict[tuple[int, int, int], tuple[IdentificationModel, ColumnMap]] = {}
_COLUMN_MAPS_LOCK = threading.Lock()


def model_column_map(model: IdentificationModel, n: int | None = None, nb: int | None = None) -> ColumnMap:
    """:func:`column_map` of ``model``, computed once per model object (kept for the 32 models used last)."""
    n = int(model.N_JOINTS) if n is None else int(n)
    nb = len(model.BASE_NAMES) if nb is None else int(nb)
    key = (id(model), n, nb)
    with _COLUMN_MAPS_LOCK:
        hit = _COLUMN_MAPS.get(key)
    if hit is not None and hit[0] is model:
        return hit[1]
    cm = column_map(model, n, nb)
    with _COLUMN_MAPS_LOCK:
        if len(_COLUMN_MAPS) >= 32:
            _COLUMN_MAPS.pop(next(iter(_COLUMN_MAPS)))
        _COLUMN_MAPS[key] = (model, cm)
    return cm


def fused_applies(traj: Trajectory, st: FilterSettings, opts: AssemblyOptions) -> bool:
    """Whether :func:`decimated_rows` gives this experiment's rows: FIR decimation with ``n_d > 1``, no row
    selection (``min_velocity``), filtered derivatives, no payload regressor to evaluate (the payload
    columns of an experiment without the payload are zeros: covered), long enough to filter, no joint held at
    an exactly constant position (the blocked path gives such a joint exactly zero velocity and acceleration,
    not the filter's rounding, whose sign would excite its Coulomb column). Otherwise the assembly's blocked
    path computes them."""
    if st.ftype != "fir" or st.n_d < 2 or opts.min_velocity is not None or opts.use_recorded_derivatives:
        return False
    if traj.n_samples and bool(np.any(np.ptp(traj.q, axis=0) == 0)):
        return False
    if opts.payload_columns and traj.loaded:
        return False
    N = traj.n_samples
    nseg = N - 2 * st.edge_samples
    return min_filter_samples(st.order) <= N and nseg >= max(min_filter_samples(st.order, st.n_d, st.ftype), st.n_d)


def outer_super_rows(st: FilterSettings, options: AssemblyOptions, n_joints: int,
                     batch_super_rows: int = BATCH_SUPER_ROWS, outer_samples: int = OUTER_SAMPLES) -> int:
    """Super-rows (``n_d`` samples each) per Butterworth block of :func:`decimated_rows`: block ``i`` holds the
    segment samples ``[i S n_d, (i + 1) S n_d)``. ``options.chunk_samples``, else the larger of
    ``outer_samples`` and ``max_chunk_mb``'s share, rounded down to whole batches."""
    nd, B = st.n_d, max(1, int(batch_super_rows))
    if options.chunk_samples is not None:
        outer = max(1, int(options.chunk_samples) // nd)
    else:
        outer = max(1, max(int(outer_samples), int(options.max_chunk_mb * 1e6 / (8.0 * 4 * n_joints))) // nd)
    return max(B, outer // B * B)


def zero_phase_kinematics(traj: Trajectory, st: FilterSettings, a: int, b: int
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The filtered ``q, dq, ddq`` of segment samples ``[a, b)`` (``a`` counted from ``st.edge_samples``) as
    :func:`decimated_rows` computes them for a Butterworth block ``[a, b)``: the zero-phase filter on the block
    with its settling margins, then central differences (the same numbers for the same block)."""
    e, N = st.edge_samples, traj.n_samples
    margin = butterworth_settle_samples(st.fs, st.cutoff_hz, st.order) + 2
    lo, hi = max(0, e + a - margin), min(N, e + b + margin)
    qf = _zero_phase_rows(traj.q[lo:hi], st.fs, st.cutoff_hz, st.order, traj.source)
    kernels = compiled_helpers()
    differences = None if kernels is None else kernels.get("differences")
    if differences is not None and qf.shape[0] >= 3 and qf.flags.c_contiguous:
        dq, ddq = np.empty_like(qf), np.empty_like(qf)
        differences(qf.shape[0], qf.shape[1], qf.ctypes.data, 1.0 / st.fs, dq.ctypes.data, ddq.ctypes.data)
    else:
        dq, ddq = differentiate(qf, 1.0 / st.fs), differentiate(qf, 1.0 / st.fs, second=True)
    off = e + a - lo
    return qf[off:off + b - a], dq[off:off + b - a], ddq[off:off + b - a]


def _polyphase(st: FilterSettings) -> np.ndarray:
    """``H[p, r] = h[p n_d + r]`` (21 x n_d, zero beyond the last tap) of the decimation FIR."""
    h = decimation_filter(st.n_d, ftype="fir", cutoff_ratio=st.cutoff_ratio)
    nd = st.n_d
    P = -(-h.size // nd)
    H = np.zeros(P * nd)
    H[:h.size] = h
    return H.reshape(P, nd)


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


_RAW_PROTO = ctypes.CFUNCTYPE(None, ctypes.c_long, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p,
                              ctypes.c_void_p)


def _raw_regressor(model: IdentificationModel) -> Callable[..., Any] | None:
    """The generated C base regressor of a compiled model called by address (``fn(N, q, dq, ddq, out)``,
    C-ordered float64 buffers), or None (NumPy kernels, a model object of another kind): the kernel then
    goes through ``model.regressor``. The same function as ``model.regressor`` calls, without its
    per-call argument checks and conversions (0.3 s of the 1 h log's 5,600 calls)."""
    owner = getattr(getattr(model, "regressor", None), "__self__", None)   # a generated package's bound method
    if not isinstance(owner, GeneratedModel):
        owner = model if isinstance(model, GeneratedModel) else None
    if owner is None or len(owner.BASE_NAMES) != len(model.BASE_NAMES) or owner.N_JOINTS != model.N_JOINTS:
        return None
    try:
        fns = owner._c_functions()
        fn = None if fns is None else fns.get(f"{owner.ROBOT}_base_regressor")
        if fn is None:
            return None
        addr = ctypes.cast(fn, ctypes.c_void_p).value
        return None if not addr else _RAW_PROTO(addr)
    except Exception:  # noqa: BLE001 - any surprise: the checked call
        return None




#: where the filtered kinematics of the segment's samples ``[a, b)`` go: ``sink(a, b, q, dq, ddq)``
KinematicsSink = Callable[[int, int, np.ndarray, np.ndarray, np.ndarray], None]


class _Rows:
    """The state of :func:`decimated_rows` on one experiment: the polyphase taps, the window of products
    ``Z`` (its last ``P - 1`` super-rows carried to the front when full), the regressor and batch buffers."""

    def __init__(self, model: IdentificationModel, traj: Trajectory, st: FilterSettings, opts: AssemblyOptions,
                 cmap: ColumnMap, sizes: tuple[int, int, int], sink: KinematicsSink | None) -> None:
        batch_super_rows, outer_samples, regressor_rows = sizes
        self.model, self.traj, self.st, self.sink = model, traj, st, sink
        n, nb = self.n, self.nb = cmap.n, cmap.nb
        nd = self.nd = st.n_d
        self.e = st.edge_samples
        self.nseg = traj.n_samples - 2 * self.e
        self.H = _polyphase(st)
        P = self.P = self.H.shape[0]             # 21 phases: output k uses super-rows k .. k + P - 1
        self.half = (P - 1) // 2                 # super-rows of zero padding before the segment (10 n_d samples)
        self.n_out = -(-self.nseg // nd)         # outputs = super-rows holding samples (s = half .. half + n_out - 1)
        U = self.U = cmap.source.size
        C = self.C = U + n                       # filtered columns: the distinct ones of W, then the torques
        B = self.B = max(1, int(batch_super_rows))
        self.margin = butterworth_settle_samples(st.fs, st.cutoff_hz, st.order) + 2
        self.outer = outer_super_rows(st, opts, n, B, outer_samples)   # super-rows per Butterworth block
        self.X = np.zeros((B, nd, C))            # super-row b, sample r of the batch: X[b, r] (W columns, then tau)
        self.X2 = self.X.reshape(B * nd, C)
        G = max(1, -(-RING_SUPER_ROWS // B))
        self.Z = np.zeros((P - 1 + G * B, P, C))  # Z[t] = H X of super-row s_base + t (zero before the segment)
        self.Y = np.empty((G * B + P, C))        # outputs of one window
        self.R = max(1, min(int(regressor_rows), B * nd))
        self.Wbuf = np.empty((self.R, n, nb))
        self.src = np.ascontiguousarray(cmap.source, dtype=np.int64)
        kernels = compiled_helpers()
        self.kernels: dict[str, Callable[..., Any]] = {} if kernels is None else kernels
        self.raw = _raw_regressor(model)
        self.k_next, self.s_base, self.zpos = 0, -(P - 1), P - 1   # next output; super-row of Z[0]; rows filled
        self.out: list[np.ndarray] = []          # outputs emitted since the last take()

    def _outputs(self, i0: int, i1: int) -> np.ndarray:
        """Window outputs i0..i1-1: ``y_i = sum_p Z[i + p, p]`` (compiled, row by row in cache; else 21
        strided vector adds), output ``k = s_base + half + i``."""
        P, C, Z = self.P, self.C, self.Z
        y = self.Y[:i1 - i0] if i1 - i0 <= self.Y.shape[0] else np.empty((i1 - i0, C))
        diagonal_sum = self.kernels.get("diagonal_sum")
        if diagonal_sum is not None:
            diagonal_sum(i1 - i0, P, C, Z.ctypes.data + i0 * P * C * 8, y.ctypes.data)
            return y
        np.copyto(y, Z[i0:i1, 0])
        for p in range(1, P):
            y += Z[i0 + p:i1 + p, p]
        return y

    def _emit(self) -> None:
        """Every output whose P super-rows are in the window (and that exists), copied to ``out``."""
        sb, zp = self.s_base, self.zpos
        i0 = self.k_next - sb - self.half
        i1 = min(zp - self.P, self.n_out - 1 - sb - self.half) + 1
        if i1 > i0:
            self.out.append(self._outputs(i0, i1).copy())
            self.k_next = sb + self.half + i1

    def _room(self, rows: int) -> int:
        """The window's next free row, after emitting and carrying its last P - 1 rows to its front when
        ``rows`` more would not fit."""
        if self.zpos + rows > self.Z.shape[0]:
            self._emit()
            zp, P = self.zpos, self.P
            self.Z[:P - 1] = self.Z[zp - (P - 1):zp]
            self.s_base += zp - (P - 1)
            self.zpos = P - 1
        return int(self.zpos)

    def _kinematics(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """Filtered q, dq, ddq around segment samples ``[a, b)`` (settling margins included) and the offset of
        sample ``a`` in them (:func:`~symoro_gen.preprocessing.filtering.filter_and_differentiate`, C-ordered:
        SciPy's ``sosfiltfilt`` along axis 0 returns them column-major, every regressor call would copy)."""
        traj, st, e, N = self.traj, self.st, self.e, self.traj.n_samples
        lo, hi = max(0, e + a - self.margin), min(N, e + b + self.margin)
        qf = _zero_phase_rows(traj.q[lo:hi], st.fs, st.cutoff_hz, st.order, traj.source)
        differences = self.kernels.get("differences")
        if differences is not None and qf.shape[0] >= 3 and qf.flags.c_contiguous:
            dq, ddq = np.empty_like(qf), np.empty_like(qf)
            differences(qf.shape[0], self.n, qf.ctypes.data, 1.0 / st.fs, dq.ctypes.data, ddq.ctypes.data)
        else:
            dq, ddq = differentiate(qf, 1.0 / st.fs), differentiate(qf, 1.0 / st.fs, second=True)
        off = e + a - lo
        if self.sink is not None:
            self.sink(a, b, qf[off:off + b - a], dq[off:off + b - a], ddq[off:off + b - a])
        return qf, dq, ddq, off

    def _gather(self, m: int, kin: tuple[np.ndarray, np.ndarray, np.ndarray], first: int) -> None:
        """The distinct columns of W on the ``m`` samples from ``first`` of ``kin`` into the batch rows."""
        n, nb, R, U, C, X2, Wbuf = self.n, self.nb, self.R, self.U, self.C, self.X2, self.Wbuf
        qf, dq, ddq = kin
        by_address = self.raw is not None and all(x.flags.c_contiguous and x.dtype == np.float64 for x in kin)
        gather = self.kernels.get("gather")
        for r0 in range(0, m, R):                           # regressor in cache-sized calls
            r1 = min(m, r0 + R)
            i0, i1 = first + r0, first + r1
            if by_address and self.raw is not None:        # the generated C, by address
                self.raw(i1 - i0, qf.ctypes.data + i0 * n * 8, dq.ctypes.data + i0 * n * 8,
                         ddq.ctypes.data + i0 * n * 8, Wbuf.ctypes.data)
                Wb = Wbuf[:r1 - r0]
            else:
                Wb = _regressor(self.model, qf[i0:i1], dq[i0:i1], ddq[i0:i1], Wbuf[:r1 - r0])
            if gather is not None:                          # Wb is Wbuf[:r1 - r0] (filled in place)
                gather(r1 - r0, Wbuf.ctypes.data, n * nb, self.src.ctypes.data, U, X2[r0:].ctypes.data, C)
            else:
                X2[r0:r1, :U] = np.take(Wb.reshape(r1 - r0, n * nb), self.src, axis=1)

    def outer_block(self, o0: int, o1: int) -> None:
        """Super-rows ``[o0, o1)``: one Butterworth block, then batches of ``B`` super-rows through the
        regressor and the polyphase product."""
        nd, B, e = self.nd, self.B, self.e
        a, b = o0 * nd, min(self.nseg, o1 * nd)            # segment samples of this outer block
        qf, dq, ddq, off = self._kinematics(a, b)
        tau = np.asarray(self.traj.tau[e + a:e + b], float)
        for s0 in range(o0, o1, B):
            s1 = min(o1, s0 + B)
            m0, m1 = (s0 - o0) * nd, min(b - a, (s1 - o0) * nd)   # rows of this batch in the outer block
            m = m1 - m0
            if m < B * nd:                                  # the last batch: zeros beyond the segment
                self.X[...] = 0.0
            self._gather(m, (qf, dq, ddq), off + m0)
            self.X2[:m, self.U:] = tau[m0:m1]
            zp = self._room(B)
            np.matmul(self.H, self.X, out=self.Z[zp:zp + B])
            self.zpos = zp + (s1 - s0)

    def finish(self) -> None:
        """The last outputs, which also use the zero padding after the segment (``half`` zero super-rows)."""
        zp = self._room(self.half)
        self.Z[zp:zp + self.half] = 0.0
        self.zpos = zp + self.half
        self._emit()

    def take(self) -> np.ndarray:
        """The outputs emitted since the last call, ``(k, C)``, in order."""
        out = self.out
        self.out = []
        if not out:
            return np.empty((0, self.C))
        return out[0] if len(out) == 1 else np.concatenate(out, axis=0)


def decimated_rows(model: IdentificationModel, traj: Trajectory, st: FilterSettings, options: AssemblyOptions,
                   cmap: ColumnMap, *, sink: KinematicsSink | None = None, batch_super_rows: int = BATCH_SUPER_ROWS,
                   outer_samples: int = OUTER_SAMPLES, regressor_rows: int = REGRESSOR_ROWS) -> Iterator[np.ndarray]:
    """The decimated rows of one experiment, one Butterworth block after another (RX-90 paper eq. 14-16; see
    the module notes), for an experiment :func:`fused_applies` to.

    Parameters
    ----------
    model : IdentificationModel
    traj : Trajectory
    st : FilterSettings
        The experiment's filters (:func:`filter_settings`).
    options : AssemblyOptions
        ``chunk_samples`` / ``max_chunk_mb`` bound the Butterworth blocks; ``blas_threads`` the products'
        threads (set while a block is computed, never while the consumer holds the rows).
    cmap : ColumnMap
        :func:`column_map` of the model (:func:`model_column_map`).
    sink : callable, optional
        ``sink(a, b, q, dq, ddq)``: the filtered kinematics of segment samples ``[a, b)`` (``a`` counted from
        ``st.edge_samples``), every segment sample once, in order.

    Yields
    ------
    ndarray, shape (k, U + n)
        The next ``k`` decimated rows, in order (row ``i`` of the experiment is full-rate sample
        ``edge_samples + i n_d``): the ``U`` distinct columns of ``W`` (entry ``cmap.entry[i]`` of ``W`` is
        column ``cmap.column[i]`` times ``cmap.scale[i]``), then the torques of the ``n`` joints (``Y``).
    """
    if traj.n_joints != cmap.n:
        raise ShapeError(f"{traj.source}: trajectory has {traj.n_joints} joints, model "
                         f"{getattr(model, 'ROBOT', '?')} has {cmap.n}")
    rows = _Rows(model, traj, st, options, cmap, (batch_super_rows, outer_samples, regressor_rows), sink)
    for o0 in range(0, rows.n_out, rows.outer):
        with blas_threads(options.blas_threads):
            rows.outer_block(o0, min(rows.n_out, o0 + rows.outer))
        y = rows.take()
        if y.shape[0]:
            yield y
    with blas_threads(options.blas_threads):
        rows.finish()
    y = rows.take()
    if y.shape[0]:
        yield y
