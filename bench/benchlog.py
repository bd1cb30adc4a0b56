"""The simulated long log the memory and speed benches read: the LWR4 (its nominal parameters) on a
10 s sum-of-sines motion repeated, 1 kHz, q noise 1e-5 rad, torque noise 0.05 N m, written block by block as
an uncompressed ``.npz`` (``times``, ``positions``, ``torques``)."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
FS = 1000.0


def simulate_lwr4_log(path: Path, seconds: float, fs: float = FS) -> None:
    """``seconds`` of the log at ``fs`` [Hz], written to ``path``."""
    sys.path.insert(0, str(ROOT))
    from symoro_gen import load_model
    from symoro_gen.simulate.recording import true_torques
    from symoro_gen.simulate.trajectories import fourier_trajectory

    m = load_model("lwr4")
    rng = np.random.default_rng(0)
    N = int(seconds * fs)
    series = fourier_trajectory(7, 10.0, 1 / fs, rng, vmax=1.5, amax=6.0).series
    t = np.arange(N) / fs
    q, tau = np.empty((N, 7)), np.empty((N, 7))
    for s in range(0, N, 200_000):
        e = min(N, s + 200_000)
        mo = series.evaluate(t[s:e])
        q[s:e] = mo.q + rng.normal(0, 1e-5, mo.q.shape)
        tau[s:e] = true_torques(m, mo.q, mo.dq, mo.ddq, m.nominal_parameters()) + rng.normal(0, 0.05, mo.q.shape)
    np.savez(path, times=t, positions=q, torques=tau)
