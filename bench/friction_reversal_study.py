"""Study: at velocity reversals, how much of the residual a static friction law leaves that the LuGre
(Dahl) state law removes, on simulated full-rate data; and whether the pre-sliding stiffness sigma0 can
be fitted at 1 kHz and at 200 Hz (docs/friction-dynamic.md).

One joint, a sum-of-sines velocity with many reversals; the true friction is LuGre (Canudas de Wit et al.
1995) with the values below; the encoder position is quantised and noisy, the velocity is its zero-phase
Butterworth-filtered central difference (as the identification does), the torque has white noise. The
static law ``Fc sign(v) + Fv v`` and the Dahl state law ``Fc phi(t; Fc/sigma0) + Fv v`` are fitted by least
squares (:func:`symoro_gen.simulate.friction_state.fit_presliding`) on the estimated velocity.

    python bench/friction_reversal_study.py [--seconds 20] [--seed 0]
"""
from __future__ import annotations

import argparse

import numpy as np
from scipy import signal

from symoro_gen.simulate.friction_state import dahl_friction, fit_presliding, lugre_friction

FC, FS, VS, SIGMA1, FV = 1.0, 1.0, 0.05, 0.0, 0.5
ENCODER = 2 * np.pi / 2 ** 20          # 20-bit encoder [rad]
NOISE_Q, NOISE_TAU = 2e-6, 0.01


def simulate(rate: float, seconds: float, rng: np.random.Generator, sigma0: float):
    """(t, q measured, true friction, measured torque) at ``rate`` Hz; the friction state integrated at 10 kHz."""
    fine = 10_000.0
    tf = np.arange(0.0, seconds, 1.0 / fine)
    freqs = np.array([0.3, 0.7, 1.3, 2.1])
    amp = rng.uniform(0.2, 0.5, freqs.size)
    ph = rng.uniform(0, 2 * np.pi, freqs.size)
    v = (amp[:, None] * np.sin(2 * np.pi * freqs[:, None] * tf + ph[:, None])).sum(0)
    q = np.cumsum(v) / fine
    f = lugre_friction(tf, v, fc=FC, fs=FS, vs=VS, sigma0=sigma0, sigma1=SIGMA1, fv=FV)
    step = int(round(fine / rate))
    t, q, f = tf[::step], q[::step], f[::step]
    qm = np.round((q + NOISE_Q * rng.standard_normal(q.size)) / ENCODER) * ENCODER
    return t, qm, f, f + NOISE_TAU * rng.standard_normal(f.size)


def velocity(t, q, cutoff_hz: float):
    fs = 1.0 / float(np.median(np.diff(t)))
    b, a = signal.butter(4, min(cutoff_hz / (fs / 2), 0.9))
    return np.gradient(signal.filtfilt(b, a, q), t)


def reversal_mask(v, t, window_s: float = 0.02):
    """Samples within ``window_s`` after a sign change of the velocity."""
    idx = np.flatnonzero(np.diff(np.sign(v)) != 0) + 1
    m = np.zeros(v.size, bool)
    for i in idx:
        m[(t >= t[i]) & (t < t[i] + window_s)] = True
    return m


def study(rate: float, seconds: float, seed: int, sigma0: float) -> dict:
    rng = np.random.default_rng(seed)
    t, q, f_true, tau = simulate(rate, seconds, rng, sigma0)
    v = velocity(t, q, cutoff_hz=min(50.0, rate / 4))
    keep = slice(int(0.5 * rate), -int(0.5 * rate))           # filter edges out
    t, v, tau, f_true = t[keep], v[keep], tau[keep], f_true[keep]
    fit = fit_presliding(t, v, tau)
    m = reversal_mask(v, t)
    As = np.column_stack([np.sign(v), v])
    rs = tau - As @ np.linalg.lstsq(As, tau, rcond=None)[0]
    rl = tau - dahl_friction(t, v, fc=fit.fc, sigma0=fit.sigma0, fv=fit.fv)
    return {"rate": rate, "sigma0": fit.sigma0, "sigma0_std": fit.std, "sigma0_half": fit.sigma0_half, "identifiable": fit.identifiable,
            "fc": fit.fc, "fv": fit.fv, "rms_static_rev": float(np.sqrt(np.mean(rs[m] ** 2))),
            "rms_state_rev": float(np.sqrt(np.mean(rl[m] ** 2))), "rms_static": fit.rms_static,
            "rms_state": fit.rms, "share_rev": float(m.mean())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--sigma0", type=float, nargs="+", default=[1e4, 1e5], help="true bristle stiffness [N m/rad]")
    a = ap.parse_args()
    print(f"truth: LuGre Fc = Fs = {FC}, Fv = {FV}; torque noise {NOISE_TAU} N m, 20-bit encoder; "
          f"{a.seconds:g} s, seed {a.seed}")
    print("sigma0 true  rate [Hz]  sigma0 fitted (std)   at half rate  identifiable  "
          "RMS at reversals static -> state  RMS overall static -> state")
    for s0 in a.sigma0:
        for rate in (1000.0, 200.0, 100.0):
            r = study(rate, a.seconds, a.seed, s0)
            print(f"{s0:11.3g}  {r['rate']:9.0f}  {r['sigma0']:10.4g} ({r['sigma0_std']:7.2g})  {r['sigma0_half']:12.4g}  "
                  f"{r['identifiable']!s:>12}  {r['rms_static_rev']:.4f} -> {r['rms_state_rev']:.4f}"
                  f"                {r['rms_static']:.4f} -> {r['rms_state']:.4f}")


if __name__ == "__main__":
    main()
