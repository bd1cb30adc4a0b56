"""Band-pass derivatives, the cut-off rules and parallel decimation against scipy.signal."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import signal

from symoro_gen.errors import DataFileError
from symoro_gen.preprocessing.filtering import (
    choose_filter_settings,
    decimate,
    decimation_filter,
    estimate_dynamics_bandwidth,
    filter_and_differentiate,
    parallel_decimate,
)

FS = 1000.0


def test_derivatives_of_a_noisy_sinusoid():
    """q = A sin(w t) + noise: the band-pass estimates recover dq, ddq inside the kept range."""
    rng = np.random.default_rng(0)
    t = np.arange(0, 6.0, 1 / FS)
    f, A = 1.5, 0.8
    w = 2 * np.pi * f
    q_true = A * np.sin(w * t)[:, None] * np.array([1.0, -0.5])
    dq_true = A * w * np.cos(w * t)[:, None] * np.array([1.0, -0.5])
    ddq_true = -A * w * w * np.sin(w * t)[:, None] * np.array([1.0, -0.5])
    noise = 1e-5
    q = q_true + noise * rng.standard_normal(q_true.shape)
    st_ = choose_filter_settings(FS, q, dynamics_bandwidth_hz=3.0)
    assert st_.cutoff_hz == pytest.approx(30.0)
    qf, dq, ddq = filter_and_differentiate(q, FS, st_.cutoff_hz, st_.order)
    e = st_.edge_samples
    s = slice(e, -e)
    assert np.abs(qf[s] - q_true[s]).max() < 5 * noise
    assert np.abs(dq[s] - dq_true[s]).max() < 2e-3 * np.abs(dq_true).max()
    assert np.abs(ddq[s] - ddq_true[s]).max() < 2e-2 * np.abs(ddq_true).max()
    # without the filter, the second difference of the noisy q is useless
    raw = (q[2:] - 2 * q[1:-1] + q[:-2]) * FS * FS
    assert np.abs(raw - ddq_true[1:-1]).max() > 0.3 * np.abs(ddq_true).max()


def test_edge_samples_remove_the_end_transients():
    """A motion that does not start at rest: the dropped edges contain the filter transient, the rest is clean."""
    t = np.arange(0, 4.0, 1 / FS)
    w = 2 * np.pi * 0.7
    q = np.sin(w * t + 0.3)[:, None]
    ddq_true = -w * w * np.sin(w * t + 0.3)[:, None]
    st_ = choose_filter_settings(FS, q, dynamics_bandwidth_hz=2.0)
    _, _, ddq = filter_and_differentiate(q, FS, st_.cutoff_hz)
    e = st_.edge_samples
    inner = np.abs(ddq[e:-e] - ddq_true[e:-e]).max() / np.abs(ddq_true).max()
    assert inner < 1e-4
    assert np.abs(ddq[:5] - ddq_true[:5]).max() / np.abs(ddq_true).max() > 10 * inner


def test_rules_and_overrides():
    s = choose_filter_settings(5000.0, dynamics_bandwidth_hz=4.0)
    assert s.cutoff_hz == pytest.approx(40.0)  # 10 f_dyn
    assert s.n_d == 100  # 0.8 * 5000 / (2 n_d) >= 5 * 4  ->  n_d <= 100
    assert s.decimation_cutoff_hz == pytest.approx(20.0)
    s2 = choose_filter_settings(5000.0, dynamics_bandwidth_hz=4.0, cutoff_hz=100.0, n_d=10)
    assert (s2.cutoff_hz, s2.n_d) == (100.0, 10) and s2.decimation_cutoff_hz == pytest.approx(200.0)
    assert "given" in s2.summary()
    s3 = choose_filter_settings(200.0, dynamics_bandwidth_hz=20.0)  # 10 f_dyn > Nyquist: clipped
    assert s3.cutoff_hz == pytest.approx(80.0) and any("clipped" in n for n in s3.notes)
    assert s3.n_d == 1
    with pytest.raises(ValueError, match="Nyquist"):
        choose_filter_settings(200.0, cutoff_hz=150.0, n_d=2)
    with pytest.raises(ValueError, match="positive integer"):
        choose_filter_settings(200.0, cutoff_hz=10.0, n_d=0)


def test_bandwidth_estimate_follows_the_signal():
    t = np.arange(0, 20.0, 1 / FS)
    slow = np.sin(2 * np.pi * 0.2 * t)[:, None]
    fast = np.column_stack([slow[:, 0], 0.3 * np.sin(2 * np.pi * 6.0 * t)])
    assert estimate_dynamics_bandwidth(slow, FS) == pytest.approx(1.0)  # the floor
    assert 5.5 < estimate_dynamics_bandwidth(fast, FS) < 7.0
    s = choose_filter_settings(FS, fast)
    assert s.bandwidth_estimated and s.cutoff_hz == pytest.approx(10 * s.dynamics_bandwidth_hz)
    assert "estimated" in s.summary()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_long_recording_bandwidth_is_welchs(seed):
    """Long recordings: the rule's spectrum equals scipy.signal.welch (Hann segments, half overlap, linear
    detrend), so the estimated bandwidth is the one computed from scipy's Welch estimate."""
    rng = np.random.default_rng(seed)
    n_seg = 2 ** 12
    t = np.arange(int(rng.integers(3 * n_seg, 9 * n_seg))) / FS
    q = np.column_stack([a * np.sin(2 * np.pi * fr * t + ph) + 20.0 * a * t + 1e-3 * rng.standard_normal(t.size)
                         for a, fr, ph in zip(rng.uniform(0.2, 2, 4), rng.uniform(1.5, 40, 4), rng.uniform(0, 6, 4))])
    f, P = signal.welch(q, fs=FS, window=np.hanning(n_seg), nperseg=n_seg, noverlap=n_seg // 2, detrend="linear", axis=0)
    c = np.cumsum(P, axis=0) / P.sum(axis=0)
    expected = max(f[min(int(np.searchsorted(c[:, j], 0.999)), f.size - 1)] for j in range(q.shape[1]))
    assert estimate_dynamics_bandwidth(q, FS, max_segment=n_seg) == pytest.approx(max(expected, 1.0), abs=1e-12)


def test_too_short_to_filter_names_the_source():
    with pytest.raises(DataFileError, match=r"run7\.csv, rows 1-10: too short to filter: 10 samples"):
        filter_and_differentiate(np.zeros((10, 2)), FS, 20.0, source="run7.csv")


@pytest.mark.parametrize("N", [997, 1000, 2048])
@pytest.mark.parametrize("n_d", [2, 5, 13, 40])
def test_decimate_equals_scipy(N, n_d):
    rng = np.random.default_rng(N + n_d)
    x = rng.standard_normal((N, 4))
    x[:, 1] = 0.0  # zero columns are skipped internally
    ref_iir = signal.decimate(x, n_d, axis=0)  # Matlab's default: Chebyshev I order 8, filtfilt
    np.testing.assert_allclose(decimate(x, n_d, ftype="iir"), ref_iir, rtol=0, atol=1e-12)
    ref_fir = signal.decimate(x, n_d, ftype="fir", axis=0)  # cut-off 1/n_d, zero-phase
    np.testing.assert_allclose(decimate(x, n_d, ftype="fir", cutoff_ratio=1.0), ref_fir, rtol=0, atol=1e-12)
    h = decimation_filter(n_d)  # default: cut-off 0.8/n_d as Matlab
    ref = signal.resample_poly(x, 1, n_d, axis=0, window=h)
    np.testing.assert_allclose(decimate(x, n_d), ref, rtol=0, atol=1e-12)
    # along another axis
    np.testing.assert_allclose(decimate(x.T, n_d, axis=1), ref.T, rtol=0, atol=1e-12)


@settings(max_examples=15, deadline=None)
@given(N=st.integers(60, 700), n_d=st.integers(2, 12), ncol=st.integers(1, 5), seed=st.integers(0, 2**16))
def test_decimate_fir_property(N, n_d, ncol, seed):
    x = np.random.default_rng(seed).standard_normal((N, ncol))
    ref = signal.resample_poly(x, 1, n_d, axis=0, window=decimation_filter(n_d))
    np.testing.assert_allclose(decimate(x, n_d), ref, rtol=0, atol=1e-12)


def test_decimation_filter_response():
    """Pass band flat to 0.8 of the new Nyquist frequency's half, aliasing band attenuated."""
    n_d = 10
    h = decimation_filter(n_d)
    w, H = signal.freqz(h, worN=8192, fs=1.0)
    nyq_new = 0.5 / n_d
    assert np.abs(np.abs(H[w < 0.5 * nyq_new]) - 1).max() < 5e-3  # Hamming ripple ~0.3 %
    assert np.abs(H[w > 1.25 * nyq_new]).max() < 3e-3


def test_parallel_decimation_keeps_the_linear_relation():
    rng = np.random.default_rng(3)
    N, n, c = 3000, 3, 5
    W = rng.standard_normal((N, n, c)).cumsum(axis=0)
    chi = rng.standard_normal(c)
    Y = W @ chi
    for ftype in ("fir", "iir"):
        Yd, Wd = parallel_decimate(Y, W, 7, ftype=ftype)
        assert Yd.shape == (429, n) and Wd.shape == (429, n, c)
        np.testing.assert_allclose(Yd, Wd @ chi, atol=1e-9 * np.abs(Y).max())
        np.testing.assert_allclose(Wd[:, 1, 2], decimate(W[:, 1, 2], 7, ftype=ftype), atol=1e-12)
