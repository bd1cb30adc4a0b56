"""IDIM-OLS vs IDIM-IV vs DIDIM on simulated closed-loop data with noisy positions.

A SCARA (4 joints) with random physical parameters tracks a random Fourier reference (0.2 Hz, 5
harmonics, 10 s at 200 Hz) under a PD controller at 6.7 Hz (``default_gains``); the logged positions
carry white noise of ``SYMORO_BENCH_NOISE_Q`` rad (default 5e-3), the logged torque 0.5 % of its range.
For each seed it prints, per estimator, the error norm relative to the truth (each parameter scaled by
``max(|chi_i|, 0.1)``), the largest |error| / sigma, the iterations and the wall time.

    PYTHONPATH=. python bench/bench_iv_didim.py [SEEDS...]

``--mc SEED M``: DIDIM's predicted sigma against the spread of its estimate over ``M`` draws of the
measurement noise on one robot and trajectory (seed ``SEED``): per parameter, the standard deviation of
the estimates over the draws divided by the mean predicted sigma (1 = exact), and the RMS of the
standardised errors ``(chi - truth) / sigma`` (1 = calibrated). Each draw starts from the truth (the
iterations are not what is measured) and computes the finite-difference sensitivity.

    PYTHONPATH=. python bench/bench_iv_didim.py --mc 4 8
"""
from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from symoro_gen.errors import IdentificationError
from symoro_gen.identification.didim import identify_didim
from symoro_gen.identification.iv import identify_iv
from symoro_gen.loader import model_for
from symoro_gen.observations import AssemblyOptions
from symoro_gen.preprocessing.trajectory import Trajectory
from symoro_gen.simulate import fourier_trajectory, random_physical_parameters
from symoro_gen.simulate.closed_loop import default_gains, simulate_closed_loop

DT = 0.005
NOISE_Q = float(os.environ.get("SYMORO_BENCH_NOISE_Q", "5e-3"))


def scenario(seed: int):
    """Model, truth, reference, gains and the noise-free closed-loop run of one seed."""
    robot, model = model_for("scara")
    rng = np.random.default_rng(seed)
    chi = np.asarray(random_physical_parameters(robot, rng, fs_range=(0.5, 2.0)))
    theta = model.base_parameters(chi)
    mot = fourier_trajectory(4, 10.0, DT, rng, amplitude=1.0, vmax=2.0, amax=10.0, base_frequency_hz=0.2)
    gains = default_gains(model, theta, mot.q, DT)
    run = simulate_closed_loop(model, theta, mot.t, mot.q, mot.dq, gains=gains)
    return model, theta, mot, gains, run, rng


def noisy_log(mot, run, rng, seed) -> Trajectory:
    return Trajectory(t=mot.t, q=run.q + NOISE_Q * rng.standard_normal(run.q.shape),
                      tau=run.tau + 0.005 * np.abs(run.tau).max(0) * rng.standard_normal(run.tau.shape),
                      source=f"seed {seed}", meta={"q_ref": mot.q})


def monte_carlo(seed: int, draws: int) -> None:
    model, theta, mot, gains, run, rng = scenario(seed)
    est, std = [], []
    t0 = time.perf_counter()
    for d in range(draws):
        fit = identify_didim(model, noisy_log(mot, run, rng, seed), AssemblyOptions(), gains=gains, start=theta,
                             jacobian="fd")
        est.append(fit.result.values)
        std.append(fit.result.std)
        print(f"draw {d + 1}/{draws}: {fit.iterations} it, {fit.statistics}, {time.perf_counter() - t0:.0f} s", flush=True)
    est, std = np.array(est), np.array(std)
    spread = est.std(0, ddof=1)
    ratio = spread / std.mean(0)
    z = (est - theta) / std
    print(f"SCARA seed {seed}, {draws} noise draws, position noise {NOISE_Q:g} rad")
    print(f"{'parameter':<8} {'truth':>10} {'spread':>10} {'sigma':>10} {'ratio':>6} {'rms z':>6}")
    for i, name in enumerate(model.BASE_NAMES):
        print(f"{name:<8} {theta[i]:>10.4g} {spread[i]:>10.3g} {std.mean(0)[i]:>10.3g} {ratio[i]:>6.2f} "
              f"{np.sqrt(np.mean(z[:, i] ** 2)):>6.2f}")
    print(f"spread / sigma: median {np.median(ratio):.2f}, range {ratio.min():.2f}-{ratio.max():.2f}; "
          f"RMS of all z {np.sqrt(np.mean(z ** 2)):.2f}; max |z| {np.abs(z).max():.1f}")


def one(seed: int) -> list[tuple]:
    model, theta, mot, gains, run, rng = scenario(seed)
    log = noisy_log(mot, run, rng, seed)
    scale = np.maximum(np.abs(theta), 0.1)
    rows = []
    for name, fn in (("IV", identify_iv), ("DIDIM", identify_didim)):
        t0 = time.perf_counter()
        try:
            kw = {"jacobian": "fd"} if fn is identify_didim else {}
            fit = fn(model, log, AssemblyOptions(), gains=gains, **kw)
        except IdentificationError as exc:
            rows.append((seed, name, None, None, 0, time.perf_counter() - t0, str(exc)[:80]))
            continue
        wall = time.perf_counter() - t0
        if name == "IV":
            e = fit.ols.values - theta
            rows.append((seed, "OLS", np.linalg.norm(e / scale), np.max(np.abs(e / fit.ols.std)), 0, 0.0, ""))
        e = fit.result.values - theta
        rows.append((seed, name, np.linalg.norm(e / scale), np.max(np.abs(e / fit.result.std)), fit.iterations, wall,
                     "" if fit.converged else "not converged"))
    return rows


def main(argv: list[str]) -> None:
    if argv[:1] == ["--mc"]:
        monte_carlo(int(argv[1]), int(argv[2]))
        return
    seeds = [int(s) for s in argv] or [3, 4, 5]
    print(f"SCARA, 10 s at 200 Hz, closed loop, position noise {NOISE_Q:g} rad")
    print(f"{'seed':>4} {'method':<6} {'|err| (scaled)':>15} {'max |err|/sigma':>16} {'iter':>5} {'time [s]':>9}")
    for s in seeds:
        for seed, name, err, z, it, wall, note in one(s):
            if err is None:
                print(f"{seed:>4} {name:<6} {'-':>15} {'-':>16} {it:>5} {wall:>9.1f}  {note}")
            else:
                print(f"{seed:>4} {name:<6} {err:>15.3f} {z:>16.1f} {it:>5} {wall:>9.1f}  {note}")


if __name__ == "__main__":
    main(sys.argv[1:])
