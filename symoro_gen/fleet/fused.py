"""The fused per-chunk kernel of a fleet run: band-pass ``q``, evaluate the base regressor, low-pass and
decimate it and fold it into the per-joint QR factors, streaming, so that the full-rate ``W`` never
exists in memory (the per-chunk kernel is the cost of everything a fleet run does).

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
* **in cache**: the regressor is evaluated ``REGRESSOR_ROWS`` samples at a time into a reused buffer, and
  its distinct columns copied straight into the layout of the matrix product (``BATCH_SUPER_ROWS``
  super-rows per product) by a compiled row gather (:data:`_KERNELS_SOURCE`; ``np.take`` without a C
  compiler, same numbers); the generated C regressor is called by address (:func:`_raw_regressor`,
  without ``model.regressor``'s per-call checks); the products fill a window of ``RING_SUPER_ROWS``
  super-rows whose outputs are summed by a compiled row-by-row loop (21 vector adds without a compiler,
  same order of additions, same numbers), its last 20 products carried to the front when it is full;
* **per-joint columns, in-place QR**: joint j's rows are non-zero only in the columns of its own entries
  (links j..n and its drive), so its factor is kept on those columns (exact) and the decimated rows are
  written scaled (compiled copy) into a Fortran-ordered ``[R_j; rows]`` buffer that LAPACK ``dgeqrf``
  factors in place every ``fold_rows`` rows (Golub & Van Loan, Matrix Computations, 4th ed., sec. 5.2,
  Householder QR; the stacking is the TSQR update of Demmel et al. 2012), every BLAS/LAPACK call of a
  log on the options' thread count (one by default);
* **the filters' rule** (``f_dyn`` when the cut-off or ``n_d`` is not given): :func:`dynamics_bandwidth`,
  ``estimate_dynamics_bandwidth``'s Welch periodogram with each segment's mean and line from sums per
  half-segment (same ``f_dyn``); the central differences of ``q`` are one compiled pass (same numbers).

The Butterworth filter of ``q`` is zero-phase (forward-backward), so it is applied per outer block of
samples with a settling margin at both ends, as :func:`~symoro_gen.observations.iter_chunks` does: its
rows equal those of this kernel to ~1e-10 relative at the block borders (the truncated transient),
exactly elsewhere. Options this kernel does not cover (``ftype="iir"``, ``n_d = 1``, ``min_velocity``,
payload columns, recorded derivatives) run through :func:`~symoro_gen.observations.iter_chunks`.
"""
from __future__ import annotations

import ctypes
import hashlib
import math
import threading
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace

import numpy as np
from scipy import signal
from scipy.linalg import lapack

from ..atomic import write_text_atomic
from ..errors import ShapeError
from ..identification.accumulate import Accumulator, accumulate
from ..model import IdentificationModel
from ..observations import AssemblyOptions, iter_chunks, observation_settings
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

__all__ = ["BATCH_SUPER_ROWS", "ColumnMap", "column_map", "dynamics_bandwidth", "filter_settings", "fold_trajectories",
           "fold_trajectory", "fused_applies"]

#: super-rows (``n_d`` samples each) per matrix product: the batch's inputs (16 x 80 x 208 doubles at
#: n_d = 80, 2 MB) and products stay in the L2/L3 caches
BATCH_SUPER_ROWS = 16
#: samples per regressor call: its output (640 x 7 x 64 doubles, 2.3 MB) is gathered while still cached
REGRESSOR_ROWS = 640
#: super-rows of products kept before the outputs are summed and the window shifted
RING_SUPER_ROWS = 128
#: full-rate samples per Butterworth block (the zero-phase filter's margins are paid once per block)
OUTER_SAMPLES = 65536
#: decimated rows per joint collected before one LAPACK QR folds them into R_j
FOLD_ROWS = 2048

_KERNELS_SOURCE = r"""
/* symoro_gen.fleet.fused: copy the distinct columns of regressor rows (row i of W, stride ldw) to
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
_KERNELS: list = []
_KERNELS_LOCK = threading.Lock()


def _c_kernels() -> dict[str, Callable] | None:
    """The compiled helpers (:data:`_KERNELS_SOURCE`: the row gather and the multi-channel sections
    filter), built once per machine with the generated models' compiler settings
    (:mod:`symoro_gen.runtime.ccompile`), or None without a C compiler (then ``np.take`` and SciPy's
    ``sosfiltfilt``: the same numbers, slower)."""
    with _KERNELS_LOCK:
        if not _KERNELS:
            fns: dict[str, Callable] | None = None
            try:
                if ctypes.sizeof(ctypes.c_long) != 8:
                    raise OSError("the helpers take 64-bit longs")
                tag = hashlib.sha256(_KERNELS_SOURCE.encode()).hexdigest()[:12]
                c_path = user_cache() / f"fleet_kernels_{tag}.c"
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
    k = _c_kernels()
    q = np.asarray(q, float)
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


def dynamics_bandwidth(q, fs: float, *, energy_fraction: float = 0.999, min_bandwidth_hz: float = 1.0,
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
    kernels = _c_kernels() if q.flags.c_contiguous else None
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
    """:func:`~symoro_gen.observations.observation_settings` (Gautier's rules for the values not given),
    with the rule's ``f_dyn`` of a long log from :func:`dynamics_bandwidth` (the same value, cheaper)."""
    kw = options.rule_keywords()
    rule = kw["dynamics_bandwidth_hz"] is None and (kw["cutoff_hz"] is None or kw["n_d"] is None)
    if not rule or traj.n_samples <= WELCH_SEGMENT or traj.q.ndim != 2:
        return observation_settings(traj, options)
    fs = 1.0 / traj.dt
    ef, fmin = kw["energy_fraction"], kw["min_bandwidth_hz"]
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
        kernels = _c_kernels()
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


def _raw_regressor(model: IdentificationModel) -> Callable | None:
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
    C = U + n                              # filtered columns: the distinct ones of W, then the torques
    B = max(1, int(batch_super_rows))
    margin = butterworth_settle_samples(fs, st.cutoff_hz, st.order) + 2
    if opts.chunk_samples is not None:
        outer = max(1, int(opts.chunk_samples) // nd)
    else:
        outer = max(1, max(int(outer_samples), int(opts.max_chunk_mb * 1e6 / (8.0 * 4 * n))) // nd)
    outer = max(B, outer // B * B)
    X = np.zeros((B, nd, C))               # super-row b, sample r of the batch: X[b, r] (W columns, then tau)
    X2 = X.reshape(B * nd, C)
    # Z[t] = H X of super-row s_base + t (zero before the segment): a window of G batches, the last P - 1
    # rows carried to the front when it is full (the state across batches: no sample filtered twice)
    G = max(1, -(-RING_SUPER_ROWS // B))
    Z = np.zeros((P - 1 + G * B, P, C))
    Y = np.empty((G * B + P, C))           # outputs of one window
    R = max(1, min(int(regressor_rows), B * nd))
    Wbuf = np.empty((R, n, nb))
    Wflat = Wbuf.reshape(R, n * nb)
    src = np.ascontiguousarray(cmap.source, dtype=np.int64)
    kernels = _c_kernels()
    gather = None if kernels is None else kernels["gather"]
    diagonal_sum = None if kernels is None else kernels["diagonal_sum"]
    differences = None if kernels is None else kernels["differences"]
    raw = _raw_regressor(model)
    Wptr = Wbuf.ctypes.data
    state = {"k_next": 0, "s_base": -(P - 1), "zpos": P - 1}   # next output; super-row of Z[0]; rows filled

    def outputs(i0: int, i1: int) -> np.ndarray:
        """Window outputs i0..i1-1: ``y_i = sum_p Z[i + p, p]`` (compiled, row by row in cache; else 21
        strided vector adds), output ``k = s_base + half + i``."""
        y = Y[:i1 - i0] if i1 - i0 <= Y.shape[0] else np.empty((i1 - i0, C))
        if diagonal_sum is not None:
            diagonal_sum(i1 - i0, P, C, Z.ctypes.data + i0 * P * C * 8, y.ctypes.data)
            return y
        np.copyto(y, Z[i0:i1, 0])
        for p in range(1, P):
            y += Z[i0 + p:i1 + p, p]
        return y

    def emit() -> None:
        """Fold every output whose P super-rows are in the window (and that exists)."""
        sb, zp = state["s_base"], state["zpos"]
        i0 = state["k_next"] - sb - half
        i1 = min(zp - P, n_out - 1 - sb - half) + 1
        if i1 > i0:
            folder.add(outputs(i0, i1))
            state["k_next"] = sb + half + i1

    def shift() -> None:
        """Emit, then carry the last P - 1 rows of the window to its front."""
        emit()
        zp = state["zpos"]
        Z[:P - 1] = Z[zp - (P - 1):zp]
        state["s_base"] += zp - (P - 1)
        state["zpos"] = P - 1

    with blas_threads(opts.blas_threads):
        for o0 in range(0, n_data, outer):
            o1 = min(n_data, o0 + outer)
            a, b = o0 * nd, min(nseg, o1 * nd)                     # segment samples of this outer block
            lo, hi = max(0, e + a - margin), min(N, e + b + margin)
            # filter_and_differentiate, with the filtered positions made C-ordered once (sosfiltfilt along
            # axis 0 returns them column-major: every regressor call would copy its slices)
            qf = _zero_phase_rows(traj.q[lo:hi], fs, st.cutoff_hz, st.order, traj.source)
            if differences is not None and qf.shape[0] >= 3 and qf.flags.c_contiguous:
                dq, ddq = np.empty_like(qf), np.empty_like(qf)
                differences(qf.shape[0], n, qf.ctypes.data, 1.0 / fs, dq.ctypes.data, ddq.ctypes.data)
            else:
                dq, ddq = differentiate(qf, 1.0 / fs), differentiate(qf, 1.0 / fs, second=True)
            by_address = raw is not None and all(a.flags.c_contiguous and a.dtype == np.float64 for a in (qf, dq, ddq))
            qp, dqp, ddqp = qf.ctypes.data, dq.ctypes.data, ddq.ctypes.data
            off = e + a - lo
            tau = np.asarray(traj.tau[e + a:e + b], float)
            for s0 in range(o0, o1, B):
                s1 = min(o1, s0 + B)
                nbt = s1 - s0
                m0, m1 = (s0 - o0) * nd, min(b - a, (s1 - o0) * nd)  # rows of this batch in the outer block
                m = m1 - m0
                if m < B * nd:                                      # the last batch: zeros beyond the segment
                    X[...] = 0.0
                for r0 in range(0, m, R):                           # regressor in cache-sized calls
                    r1 = min(m, r0 + R)
                    i0, i1 = off + m0 + r0, off + m0 + r1
                    if raw is not None and by_address:              # the generated C, by address
                        raw(i1 - i0, qp + i0 * n * 8, dqp + i0 * n * 8, ddqp + i0 * n * 8, Wptr)
                        Wb = Wbuf[:r1 - r0]
                    else:
                        Wb = _regressor(model, qf[i0:i1], dq[i0:i1], ddq[i0:i1], Wbuf[:r1 - r0])
                    if gather is not None:                          # Wb is Wbuf[:r1 - r0] (filled in place)
                        gather(r1 - r0, Wflat.ctypes.data, n * nb, src.ctypes.data, U, X2[r0:].ctypes.data, C)
                    else:
                        X2[r0:r1, :U] = np.take(Wb.reshape(r1 - r0, n * nb), src, axis=1)
                X2[:m, U:] = tau[m0:m1]
                if state["zpos"] + B > Z.shape[0]:
                    shift()
                zp = state["zpos"]
                np.matmul(H, X, out=Z[zp:zp + B])
                state["zpos"] = zp + nbt
        # the last outputs also use the zero padding after the segment: half zero super-rows
        if state["zpos"] + half > Z.shape[0]:
            shift()
        zp = state["zpos"]
        Z[zp:zp + half] = 0.0
        state["zpos"] = zp + half
        emit()


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
    # every BLAS and LAPACK call of the kernel with the options' threads (default 1), the rule's sums and the
    # last QR fold (result()) included: a multi-threaded OpenBLAS spent 0.4 s CPU on each 2k-row dgeqrf
    # here (0.004 s on one thread), which a process outside Dask's nanny (threads:N, the CLI) paid per log
    with blas_threads(opts.blas_threads):
        return _fold_one(model, traj, opts, acc, cmap, batch_super_rows, outer_samples, regressor_rows, fold_rows)


def _fold_one(model: IdentificationModel, traj: Trajectory, opts: AssemblyOptions, acc: Accumulator | None,
              cmap: ColumnMap | None, batch_super_rows: int, outer_samples: int, regressor_rows: int,
              fold_rows: int) -> Accumulator:
    st = filter_settings(traj, opts)
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
    return folder.result()


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
