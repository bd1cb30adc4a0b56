"""Gautier's pre-processing: band-pass derivatives of q and parallel decimation.

The identification model ``Y = W(q, dq, ddq) chi`` ([GB-gains] eq. 14-16) needs
velocities and accelerations that are not measured. Following Gautier ([G1997], "Dynamic
identification of robots with power model", ICRA) and the two papers of the project:

1. **Band-pass derivative filter** of the measured positions: a zero-phase Butterworth low-pass
   (forward-backward, :func:`scipy.signal.sosfiltfilt`, ends padded by odd extension over three
   periods of the cut-off) of ``q`` followed by central differences; four periods of the cut-off are
   then dropped at each end of each experiment (edge transients).
   Low-pass + differentiation is a band-pass filter for ``dq`` and ``ddq``; run forward and
   backward it introduces no phase lag. Rule: the cut-off must be well above the bandwidth of the
   robot's dynamics, ``f_c >= 10 f_dyn`` (Gautier 1997), so that the filter does not distort the
   dynamics while it removes the noise amplified by differentiation.
2. **Parallel decimation** of ``Y`` and of every column of ``W``: the same low-pass filter is
   applied to the torque samples and to each regressor column, then one sample in ``n_d`` is kept
   (what Matlab's / SciPy's ``decimate`` do). This removes the torque ripple the rigid model does
   not explain and reduces the number of rows; since the same linear filter is applied to both
   sides, ``Y = W chi`` still holds after decimation. The low-pass cut-off is that of Matlab's
   ``decimate``, ``f_p = 0.8 f_s / (2 n_d)``; ``n_d`` is chosen as the largest integer keeping
   ``f_p >= decimation_margin * f_dyn`` (default margin 5).

``f_dyn`` is given by the caller (``dynamics_bandwidth_hz``) or estimated from the data as the
frequency below which ``energy_fraction`` (default 99.9 %) of the energy of the detrended joint
positions lies, maximum over the joints that move, floored at ``min_bandwidth_hz`` (default 1 Hz:
closed-loop position bandwidths of robots are rarely lower). A joint whose motion is at the noise
level (:func:`~symoro_gen.preprocessing.motion.noise_level_joints`: position RMS below 30 x the noise
estimated from its second differences) is left out: its spectrum is the noise's, flat up to the
Nyquist frequency, and would set the cut-off there (no low-pass, no decimation) for every joint. Every choice is overridable and reported in a
:class:`FilterSettings` (``summary()`` prints the rule and the numbers).

Two decimation filters are offered (both zero-phase):

* ``ftype="fir"`` (default): a linear-phase Hamming-window FIR of length ``20 n_d + 1`` with cut-off
  ``cutoff_ratio / n_d`` of the Nyquist frequency (``cutoff_ratio = 0.8`` by default, the Matlab
  rule), applied centred on each kept sample with zero padding outside the signal, exactly as
  :func:`scipy.signal.resample_poly` (and so ``scipy.signal.decimate(x, n_d, ftype="fir")`` when
  ``cutoff_ratio = 1``). Each output depends on ``10 n_d`` samples on each side only, which makes
  block-wise (streaming) processing exact; it is computed with dense matrix products (BLAS).
* ``ftype="iir"``: Chebyshev type I of order 8, 0.05 dB ripple, cut-off ``0.8 / n_d``, run forward and
  backward — exactly ``scipy.signal.decimate(x, n_d)`` (Matlab's default ``decimate``).
"""
from __future__ import annotations

import ctypes
import math
from collections.abc import Sequence
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import as_strided
from scipy import signal

from ..errors import DataFileError, Problem
from .motion import noise_level_joints

__all__ = [
    "FilterSettings",
    "choose_filter_settings",
    "estimate_dynamics_bandwidth",
    "bandwidth_from_power",
    "still_note",
    "lowpass_positions",
    "differentiate",
    "filter_and_differentiate",
    "decimation_filter",
    "decimate",
    "parallel_decimate",
    "min_filter_samples",
    "butterworth_settle_samples",
]

#: Gautier's rule: Butterworth cut-off >= 10 x the dynamics bandwidth.
CUTOFF_FACTOR = 10.0
#: the decimation low-pass cut-off (0.8 f_s / (2 n_d)) is kept >= this factor x f_dyn.
DECIMATION_MARGIN = 5.0
#: Matlab / SciPy ``decimate`` place the low-pass at 0.8 x the new Nyquist frequency.
DECIMATION_CUTOFF_RATIO = 0.8
#: the Butterworth pass pads the ends by odd extension over this many periods of its cut-off.
PAD_PERIODS = 3.0
#: default samples dropped at each end: this many periods of the Butterworth cut-off.
EDGE_PERIODS = 4.0


@dataclass(frozen=True)
class FilterSettings:
    """The pre-processing choices for one experiment (all in SI units).

    Attributes
    ----------
    fs : float
        Sampling frequency of the recording [Hz].
    dynamics_bandwidth_hz : float
        ``f_dyn`` used by the rules [Hz].
    bandwidth_estimated : bool
        True when ``f_dyn`` was estimated from the positions (see :func:`estimate_dynamics_bandwidth`).
    cutoff_hz : float
        Cut-off of the zero-phase Butterworth low-pass applied to ``q`` [Hz].
    order : int
        Butterworth order (applied twice: forward and backward).
    n_d : int
        Decimation factor (one sample kept in ``n_d``); 1 means no decimation.
    decimation_cutoff_hz : float
        Cut-off of the decimation low-pass, ``cutoff_ratio * fs / (2 n_d)`` [Hz] (``inf`` when ``n_d == 1``).
    ftype : str
        ``"fir"`` or ``"iir"`` decimation filter.
    cutoff_ratio : float
        Decimation cut-off relative to the decimated Nyquist frequency (0.8 as Matlab).
    edge_samples : int
        Samples dropped at each end of the experiment after differentiation (filter edge effects).
    notes : tuple of str
        Which values were set by the caller and which by the rules, and any clipping applied.
    """

    fs: float
    dynamics_bandwidth_hz: float
    bandwidth_estimated: bool
    cutoff_hz: float
    order: int
    n_d: int
    decimation_cutoff_hz: float
    ftype: str
    cutoff_ratio: float
    edge_samples: int
    notes: tuple[str, ...] = ()

    def summary(self) -> str:
        """Human-readable report of the chosen values and why."""
        lines = [
            f"sampling frequency        f_s   = {self.fs:.6g} Hz",
            f"dynamics bandwidth        f_dyn = {self.dynamics_bandwidth_hz:.4g} Hz"
            + (" (estimated from the positions)" if self.bandwidth_estimated else " (given)"),
            f"Butterworth on q (x2)     order {self.order}, f_c = {self.cutoff_hz:.4g} Hz"
            f" ({self.cutoff_hz / self.dynamics_bandwidth_hz:.3g} f_dyn)",
            "derivatives               central differences of the filtered q",
            f"parallel decimation       n_d = {self.n_d}, {self.ftype.upper()} low-pass at "
            f"{self.decimation_cutoff_hz:.4g} Hz, new rate {self.fs / self.n_d:.4g} Hz",
            f"edge samples dropped      {self.edge_samples} at each end",
        ]
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# rules
# ---------------------------------------------------------------------------------------------
def estimate_dynamics_bandwidth(q, fs: float, *, energy_fraction: float = 0.999,
                                min_bandwidth_hz: float = 1.0, max_segment: int = 2 ** 16,
                                skip: Sequence[int] | None = None) -> float:
    """Frequency below which ``energy_fraction`` of the position energy lies (max over the joints that move).

    Parameters
    ----------
    q : array_like, shape (N, n)
        Joint positions [rad or m].
    fs : float
        Sampling frequency [Hz].
    energy_fraction : float
        Fraction of the energy of the linearly detrended, Hann-windowed positions.
    min_bandwidth_hz : float
        Floor of the result [Hz].
    max_segment : int
        Longer recordings are analysed by Welch's method with segments of this length.
    skip : sequence of int, optional
        0-based joints left out; default the joints whose motion is at the noise level
        (:func:`~symoro_gen.preprocessing.motion.noise_level_joints`).

    Returns
    -------
    float
        ``f_dyn`` [Hz], at least ``min_bandwidth_hz`` and at most ``fs / 2``.
    """
    q = np.asarray(q, float)
    if q.ndim == 1:
        q = q[:, None]
    if q.shape[0] < 8:
        return float(min_bandwidth_hz)
    if q.shape[0] <= max_segment:
        qd = signal.detrend(q, axis=0, type="linear")
        w = np.hanning(q.shape[0])[:, None]
        P = np.abs(np.fft.rfft(qd * w, axis=0)) ** 2
        f = np.fft.rfftfreq(q.shape[0], 1.0 / fs)
    else:  # long recordings: Welch average of linearly detrended, half-overlapping segments
        # (the line of each segment removed by its closed-form least-squares fit on centred time, joints
        # along the contiguous axis: the same periodogram as scipy.signal.detrend + rfft to 1e-16, half the time)
        m = int(max_segment)
        w = np.hanning(m)
        tc = np.arange(m) - (m - 1) / 2.0
        f = np.fft.rfftfreq(m, 1.0 / fs)
        P = np.zeros((f.size, q.shape[1]))
        buf = np.empty((q.shape[1], m))
        for s in range(0, q.shape[0] - m + 1, m // 2):
            seg = q[s:s + m].T
            np.subtract(seg, seg.mean(axis=1)[:, None], out=buf)
            buf -= ((seg @ tc) / (tc @ tc))[:, None] * tc
            buf *= w
            X = np.fft.rfft(buf, axis=1)
            P += (X.real ** 2 + X.imag ** 2).T
    left_out = noise_level_joints(q) if skip is None else tuple(skip)
    return bandwidth_from_power(P, f, fs, energy_fraction=energy_fraction, min_bandwidth_hz=min_bandwidth_hz,
                                skip=left_out)


def bandwidth_from_power(P: np.ndarray, f: np.ndarray, fs: float, *, energy_fraction: float,
                         min_bandwidth_hz: float, skip: Sequence[int] = ()) -> float:
    """The rule's ``f_dyn`` from position power spectra ``P`` (frequencies ``f``, one column per joint): the
    largest frequency below which ``energy_fraction`` of a joint's energy lies, over the joints not in
    ``skip``, within ``[min_bandwidth_hz, fs / 2]``."""
    best = 0.0
    tot = P.sum(axis=0)
    for j in range(P.shape[1]):
        if tot[j] <= 0 or j in skip:
            continue
        c = np.cumsum(P[:, j]) / tot[j]
        k = min(int(np.searchsorted(c, energy_fraction)), f.size - 1)
        best = max(best, float(f[k]))
    return float(min(max(best, min_bandwidth_hz), fs / 2.0))


def still_note(joints: Sequence[int]) -> str:
    """The :class:`FilterSettings` note naming the joints (0-based) left out of ``f_dyn``."""
    return (f"f_dyn: joint(s) {', '.join(str(j + 1) for j in joints)} left out: motion at the noise level "
            "(position RMS below 30 x the noise of its second differences)")


def butterworth_settle_samples(fs: float, cutoff_hz: float, order: int = 4, *, rel_tol: float = 1e-10) -> int:
    """Samples after which the Butterworth impulse response stays below ``rel_tol`` of its peak."""
    sos = signal.butter(order, cutoff_hz, fs=fs, output="sos")
    n = int(math.ceil(40.0 * fs / cutoff_hz)) + 10
    x = np.zeros(n)
    x[0] = 1.0
    h = signal.sosfilt(sos, x)
    above = np.nonzero(np.abs(h) > rel_tol * np.abs(h).max())[0]
    return int(above[-1]) + 1 if above.size else 1


def min_filter_samples(order: int = 4, n_d: int = 1, ftype: str = "fir") -> int:
    """Fewest samples the zero-phase filters accept (``sosfiltfilt`` pads ``3 (2 n_sections + 1)``)."""
    n_sec = (order + 1) // 2
    need = 3 * (2 * n_sec + 1) + 1
    if n_d > 1 and ftype == "iir":
        need = max(need, 3 * (2 * 4 + 1) + 1)
    return max(need, 3)


@dataclass(frozen=True)
class FilterRule:
    """The constants of Gautier's rules for choosing the filters (module docstring; [G1997] for the cut-off,
    [GB-gains] eq. 14-16 for the decimation factor).

    Attributes
    ----------
    cutoff_factor : float
        Butterworth cut-off = ``cutoff_factor * f_dyn`` (>= 10, [G1997]).
    decimation_margin : float
        Decimated Nyquist frequency >= ``decimation_margin * f_dyn``.
    cutoff_ratio : float
        Pass band of the decimation low-pass as a share of the decimated Nyquist frequency.
    energy_fraction : float
        ``f_dyn``: the frequency below which this share of the position energy lies.
    min_bandwidth_hz : float
        Floor of the estimated ``f_dyn`` [Hz].
    max_cutoff_fraction : float
        The cut-off is clipped to this share of the Nyquist frequency.
    """

    cutoff_factor: float = CUTOFF_FACTOR
    decimation_margin: float = DECIMATION_MARGIN
    cutoff_ratio: float = DECIMATION_CUTOFF_RATIO
    energy_fraction: float = 0.999
    min_bandwidth_hz: float = 1.0
    max_cutoff_fraction: float = 0.8


def choose_filter_settings(
    fs: float,
    q=None,
    *,
    dynamics_bandwidth_hz: float | None = None,
    cutoff_hz: float | None = None,
    n_d: int | None = None,
    order: int = 4,
    ftype: str = "fir",
    edge_samples: int | None = None,
    rule: FilterRule | None = None,
) -> FilterSettings:
    """Apply Gautier's rules (see the module docstring); any value given is kept as is.

    Parameters
    ----------
    fs : float
        Sampling frequency [Hz].
    q : array_like, shape (N, n), optional
        Positions, used to estimate ``f_dyn`` when neither ``dynamics_bandwidth_hz`` nor both
        ``cutoff_hz`` and ``n_d`` are given.
    dynamics_bandwidth_hz : float, optional
        ``f_dyn`` [Hz].
    cutoff_hz : float, optional
        Butterworth cut-off [Hz]; default ``cutoff_factor * f_dyn`` clipped to
        ``max_cutoff_fraction * fs / 2``.
    n_d : int, optional
        Decimation factor; default the largest keeping ``cutoff_ratio * fs / (2 n_d) >=
        decimation_margin * f_dyn``.
    order : int
        Butterworth order.
    ftype : {"fir", "iir"}
        Decimation filter (see module docstring).
    edge_samples : int, optional
        Samples dropped at each end; default ``ceil(4 fs / cutoff_hz)`` (four periods of the cut-off:
        with the odd-extension padding over three periods, the acceleration error left there is
        ~1e-5 of its peak for smooth motions).
    rule : FilterRule, optional
        The constants of Gautier's rules (default :class:`FilterRule`'s: [G1997], [GB-gains] eq. 14-16).

    Returns
    -------
    FilterSettings
    """
    rule = FilterRule() if rule is None else rule
    cutoff_factor, decimation_margin, cutoff_ratio = rule.cutoff_factor, rule.decimation_margin, rule.cutoff_ratio
    energy_fraction, min_bandwidth_hz = rule.energy_fraction, rule.min_bandwidth_hz
    max_cutoff_fraction = rule.max_cutoff_fraction
    if not (fs > 0 and np.isfinite(fs)):
        raise ValueError(f"sampling frequency must be positive, got {fs!r}")
    if ftype not in ("fir", "iir"):
        raise ValueError(f"ftype must be 'fir' or 'iir', got {ftype!r}")
    notes: list[str] = []
    estimated = False
    if dynamics_bandwidth_hz is None:
        if q is not None and (cutoff_hz is None or n_d is None):
            still = noise_level_joints(q)
            f_dyn = estimate_dynamics_bandwidth(q, fs, energy_fraction=energy_fraction,
                                                min_bandwidth_hz=min_bandwidth_hz, skip=still)
            estimated = True
            notes.append(f"f_dyn: {100 * energy_fraction:g} % of the position energy lies below it "
                         f"(floor {min_bandwidth_hz:g} Hz)")
            if still:
                notes.append(still_note(still))
        elif cutoff_hz is not None:
            f_dyn = cutoff_hz / cutoff_factor
            notes.append("f_dyn taken as cutoff / cutoff_factor (no data to estimate it)")
        else:
            raise ValueError("give dynamics_bandwidth_hz, cutoff_hz or the positions q to choose the filters")
    else:
        f_dyn = float(dynamics_bandwidth_hz)
        if not f_dyn > 0:
            raise ValueError(f"dynamics_bandwidth_hz must be positive, got {dynamics_bandwidth_hz!r}")
    nyq = fs / 2.0
    if cutoff_hz is None:
        fc = cutoff_factor * f_dyn
        if fc > max_cutoff_fraction * nyq:
            notes.append(f"Butterworth cut-off {fc:.4g} Hz clipped to {max_cutoff_fraction:g} x Nyquist")
            fc = max_cutoff_fraction * nyq
        else:
            notes.append(f"Butterworth cut-off = {cutoff_factor:g} f_dyn (Gautier 1997)")
    else:
        fc = float(cutoff_hz)
        notes.append("Butterworth cut-off given")
        if not (0 < fc < nyq):
            raise ValueError(f"cutoff_hz = {cutoff_hz} Hz must lie in (0, {nyq:g}) Hz (Nyquist)")
    if n_d is None:
        nd = int(math.floor(cutoff_ratio * fs / (2.0 * decimation_margin * f_dyn)))
        nd = max(nd, 1)
        notes.append(f"n_d: largest with {cutoff_ratio:g} f_s / (2 n_d) >= {decimation_margin:g} f_dyn")
    else:
        nd = int(n_d)
        if nd < 1 or nd != n_d:
            raise ValueError(f"n_d must be a positive integer, got {n_d!r}")
        notes.append("n_d given")
    fp = cutoff_ratio * fs / (2.0 * nd) if nd > 1 else float("inf")
    if fp > fc:
        notes.append(f"the decimation low-pass ({fp:.4g} Hz) passes frequencies the Butterworth filter "
                     f"({fc:.4g} Hz) removed from q: there W (filtered) and Y (raw) disagree")
    if edge_samples is None:
        edge = int(math.ceil(EDGE_PERIODS * fs / fc))
    else:
        edge = int(edge_samples)
        if edge < 0:
            raise ValueError("edge_samples must be >= 0")
    return FilterSettings(fs=float(fs), dynamics_bandwidth_hz=float(f_dyn), bandwidth_estimated=estimated,
                          cutoff_hz=float(fc), order=int(order), n_d=nd, decimation_cutoff_hz=float(fp),
                          ftype=ftype, cutoff_ratio=float(cutoff_ratio), edge_samples=edge, notes=tuple(notes))


# ---------------------------------------------------------------------------------------------
# band-pass derivatives
# ---------------------------------------------------------------------------------------------
def _too_short(source: str, n: int, need: int, what: str) -> DataFileError:
    return DataFileError([Problem(source, f"rows 1-{n}", "", f"too short to {what}: {n} samples, "
                                  f"at least {need} needed")])


def lowpass_positions(q, fs: float, cutoff_hz: float, order: int = 4, *, source: str = "<memory>"):
    """Zero-phase Butterworth low-pass of the positions along axis 0 (``sosfiltfilt``; [G1997], [GB-gains] eq. 14).

    Parameters
    ----------
    q : array_like, shape (N, n)
    fs, cutoff_hz : float
        Sampling frequency and cut-off [Hz].
    order : int
        Butterworth order (the magnitude response is squared by the forward-backward pass).
    source : str
        Name used in error messages.

    Returns
    -------
    ndarray, shape (N, n)
    """
    q = np.asarray(q, float)
    need = min_filter_samples(order)
    if q.shape[0] < need:
        raise _too_short(source, q.shape[0], need, "filter")
    sos = signal.butter(order, cutoff_hz, fs=fs, output="sos")
    # odd extension over PAD_PERIODS periods of the cut-off (SciPy's default, 3 (2 n_sec + 1) samples,
    # leaves large acceleration transients at the ends)
    padlen = min(q.shape[0] - 1, int(math.ceil(PAD_PERIODS * fs / cutoff_hz)))
    return signal.sosfiltfilt(sos, q, axis=0, padlen=padlen)


def differentiate(x, dt: float, *, second: bool = False):
    """Central differences along axis 0.

    First derivative: ``(x[k+1] - x[k-1]) / (2 dt)``; second derivative (``second=True``):
    ``(x[k+1] - 2 x[k] + x[k-1]) / dt**2``; one-sided at both ends.

    Parameters
    ----------
    x : array_like, shape (N, ...)
    dt : float
        Sampling period [s].
    """
    x = np.asarray(x, float)
    if not second:
        return np.gradient(x, dt, axis=0)
    out = np.empty_like(x)
    if x.shape[0] < 3:
        out[...] = 0.0
        return out
    out[1:-1] = (x[2:] - 2.0 * x[1:-1] + x[:-2]) / (dt * dt)
    out[0] = out[1]
    out[-1] = out[-2]
    return out


def filter_and_differentiate(q, fs: float, cutoff_hz: float, order: int = 4, *, source: str = "<memory>"):
    """Band-pass estimates of ``q``, ``dq``, ``ddq`` from measured positions ([G1997]; [GB-gains] eq. 14).

    Returns
    -------
    (q_f, dq, ddq) : ndarrays of shape (N, n)
        Filtered positions [rad], velocities [rad/s] and accelerations [rad/s^2].
    """
    qf = lowpass_positions(q, fs, cutoff_hz, order, source=source)
    dt = 1.0 / fs
    return qf, differentiate(qf, dt), differentiate(qf, dt, second=True)


# ---------------------------------------------------------------------------------------------
# decimation
# ---------------------------------------------------------------------------------------------
_BLAS_CONTROLS: list | None = None


def _openblas_thread_controls() -> list:
    """(get, set) thread-count functions of the OpenBLAS libraries loaded in this process (Linux)."""
    global _BLAS_CONTROLS
    if _BLAS_CONTROLS is not None:
        return _BLAS_CONTROLS
    out = []
    try:
        with open("/proc/self/maps") as f:
            paths = sorted({ln.split()[-1] for ln in f if "openblas" in ln.lower() and ".so" in ln})
    except OSError:
        paths = []
    for p in paths:
        try:
            lib = ctypes.CDLL(p)
        except OSError:
            continue
        for prefix in ("scipy_openblas", "openblas"):
            for suffix in ("64_", "_64", ""):
                get = getattr(lib, f"{prefix}_get_num_threads{suffix}", None)
                set_ = getattr(lib, f"{prefix}_set_num_threads{suffix}", None)
                if get is not None and set_ is not None:
                    out.append((get, set_))
                    break
    _BLAS_CONTROLS = out
    return out


@contextmanager
def blas_threads(n: int | None = 1):
    """Run the enclosed BLAS calls with ``n`` OpenBLAS threads (restored afterwards; ``None``: unchanged).

    The FIR decimation makes many medium-size matrix products; on a loaded machine a multi-threaded
    OpenBLAS spends most of their time synchronising its threads (measured 4x slower on 2 shared cores).
    """
    controls = _openblas_thread_controls() if n is not None else []
    before = [get() for get, _ in controls]
    if n is not None:
        for _, set_ in controls:
            set_(int(n))
    try:
        yield
    finally:
        for (_, set_), k in zip(controls, before):
            set_(k)


def decimation_filter(n_d: int, *, ftype: str = "fir", cutoff_ratio: float = DECIMATION_CUTOFF_RATIO,
                      iir_order: int = 8):
    """Coefficients of the decimation low-pass.

    Returns
    -------
    ndarray
        FIR taps, shape (20 n_d + 1,), for ``ftype="fir"``; SOS array for ``ftype="iir"``.
    """
    if n_d < 2:
        raise ValueError("no decimation filter for n_d < 2")
    if ftype == "fir":
        return signal.firwin(20 * n_d + 1, cutoff_ratio / n_d, window="hamming")
    if ftype == "iir":
        return signal.cheby1(iir_order, 0.05, cutoff_ratio / n_d, output="sos")
    raise ValueError(f"ftype must be 'fir' or 'iir', got {ftype!r}")


def _fir_group_matrix(h: np.ndarray, n_d: int, group: int) -> np.ndarray:
    L = h.size
    D = np.zeros((group, (group - 1) * n_d + L))
    for i in range(group):
        D[i, i * n_d:i * n_d + L] = h
    return D


def fir_decimate_padded(buf: np.ndarray, h: np.ndarray, n_d: int, n_out: int, group: int) -> np.ndarray:
    """Outputs ``y[k] = sum_m h[m] buf[k n_d + m]`` for k < n_out; ``buf`` 2-D C-contiguous and long enough."""
    L = h.size
    G = -(-n_out // group)
    Lw = (group - 1) * n_d + L
    need = (G - 1) * group * n_d + Lw
    if buf.shape[0] < need:
        raise ValueError("internal: FIR buffer too short")
    D = _fir_group_matrix(h, n_d, group)
    s0, s1 = buf.strides
    V = as_strided(buf, shape=(G, Lw, buf.shape[1]), strides=(group * n_d * s0, s0, s1), writeable=False)
    return np.matmul(D, V).reshape(G * group, buf.shape[1])[:n_out]


def fir_buffer_length(n_out: int, n_d: int, L: int, group: int) -> int:
    """Rows the padded buffer of :func:`fir_decimate_padded` needs for ``n_out`` outputs."""
    G = -(-n_out // group)
    return (G - 1) * group * n_d + (group - 1) * n_d + L


def fir_group_size(n_d: int) -> int:
    """Outputs computed per matrix product by :func:`fir_decimate_padded`."""
    return 16


def fir_decimate(x: np.ndarray, h: np.ndarray, n_d: int) -> np.ndarray:
    """FIR decimation aligned as ``scipy.signal.resample_poly(x, 1, n_d, window=h)`` (axis 0, 2-D x)."""
    N, C = x.shape
    L = h.size
    half = (L - 1) // 2
    n_out = -(-N // n_d)
    group = fir_group_size(n_d)
    rows = fir_buffer_length(n_out, n_d, L, group)
    cols = np.flatnonzero(np.any(x != 0.0, axis=0))
    out = np.zeros((n_out, C))
    if cols.size == 0:
        return out
    buf = np.zeros((max(rows, half + N), cols.size))
    buf[half:half + N] = x[:, cols] if cols.size < C else x
    out[:, cols] = fir_decimate_padded(buf, h, n_d, n_out, group)
    return out


def decimate(x, n_d: int, *, axis: int = 0, ftype: str = "fir", cutoff_ratio: float = DECIMATION_CUTOFF_RATIO,
             source: str = "<memory>"):
    """Zero-phase low-pass and keep one sample in ``n_d`` (samples 0, n_d, 2 n_d, ...).

    Parameters
    ----------
    x : array_like, shape (N, ...) (along ``axis``)
    n_d : int
        Decimation factor (1 returns a copy).
    ftype : {"fir", "iir"}
        ``"iir"`` equals ``scipy.signal.decimate(x, n_d, axis=axis)``; ``"fir"`` equals
        ``scipy.signal.resample_poly(x, 1, n_d, axis=axis, window=decimation_filter(n_d))``
        (with ``cutoff_ratio=1``: ``scipy.signal.decimate(x, n_d, ftype="fir", axis=axis)``).
    cutoff_ratio : float
        Low-pass cut-off relative to the decimated Nyquist frequency.

    Returns
    -------
    ndarray
        ``ceil(N / n_d)`` samples along ``axis``.
    """
    x = np.asarray(x, float)
    n_d = int(n_d)
    if n_d < 1:
        raise ValueError(f"n_d must be >= 1, got {n_d}")
    if n_d == 1:
        return x.copy()
    xm = np.moveaxis(x, axis, 0)
    N = xm.shape[0]
    flat = xm.reshape(N, -1)
    if ftype == "iir":
        sos = decimation_filter(n_d, ftype="iir", cutoff_ratio=cutoff_ratio)
        padlen = 3 * (2 * sos.shape[0] + 1)
        if padlen >= N:
            raise _too_short(source, N, padlen + 1, f"decimate by {n_d} (IIR)")
        y = signal.sosfiltfilt(sos, flat, axis=0)[::n_d]
    elif ftype == "fir":
        h = decimation_filter(n_d, ftype="fir", cutoff_ratio=cutoff_ratio)
        with blas_threads(1):
            y = fir_decimate(np.ascontiguousarray(flat), h, n_d)
    else:
        raise ValueError(f"ftype must be 'fir' or 'iir', got {ftype!r}")
    return np.moveaxis(y.reshape((y.shape[0],) + xm.shape[1:]), 0, axis)


def parallel_decimate(Y, W, n_d: int, *, ftype: str = "fir", cutoff_ratio: float = DECIMATION_CUTOFF_RATIO,
                      source: str = "<memory>"):
    """Decimate ``Y`` and every column of ``W`` with the same filter ([GB-gains] eq. 15-16).

    Parameters
    ----------
    Y : array_like, shape (N, n)
        Torque samples of one experiment.
    W : array_like, shape (N, n, c)
        Regressor samples.

    Returns
    -------
    (Y_d, W_d) : ndarrays of shapes (ceil(N/n_d), n) and (ceil(N/n_d), n, c)
    """
    Y = np.asarray(Y, float)
    W = np.asarray(W, float)
    if Y.shape[0] != W.shape[0]:
        raise ValueError(f"Y has {Y.shape[0]} samples, W has {W.shape[0]}")
    N = Y.shape[0]
    both = np.concatenate([Y.reshape(N, -1), W.reshape(N, -1)], axis=1)
    d = decimate(both, n_d, ftype=ftype, cutoff_ratio=cutoff_ratio, source=source)
    ny = int(np.prod(Y.shape[1:], dtype=int))
    return d[:, :ny].reshape((d.shape[0],) + Y.shape[1:]), d[:, ny:].reshape((d.shape[0],) + W.shape[1:])
