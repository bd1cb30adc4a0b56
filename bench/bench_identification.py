"""Identification benchmark: one hour of 7-joint data at 1 kHz (3.6 million samples,
simulated LWR4 with its URDF nominal values): filter, decimate, assemble W and solve OLS and
TLS, streaming the data in chunks. Targets: <= 60 s and peak memory <= 1.5 GB on 2 cores.

The recording is simulated first, block by block, in a separate process and written as an
uncompressed .npz; the timed process memory-maps it (the file pages it touches count in its
resident memory) and runs the pipeline. Peak memory is that process's maximum resident set size.
"""
from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
HOURS = float(os.environ.get("SYMORO_BENCH_HOURS", "1.0"))
FS = 1000.0


def simulate(path: Path) -> None:
    sys.path.insert(0, str(ROOT))
    from symoro_gen import load_model
    from symoro_gen.simulate.recording import true_torques
    from symoro_gen.simulate.trajectories import fourier_trajectory

    m = load_model("lwr4")
    rng = np.random.default_rng(0)
    chi = m.nominal_parameters()
    N = int(HOURS * 3600 * FS)
    series = fourier_trajectory(7, 10.0, 1 / FS, rng, vmax=1.5, amax=6.0).series
    t = np.arange(N) / FS
    q = np.empty((N, 7))
    tau = np.empty((N, 7))
    B = 200_000
    for s in range(0, N, B):
        e = min(N, s + B)
        mo = series.evaluate(t[s:e])
        q[s:e] = mo.q + rng.normal(0, 1e-5, mo.q.shape)
        tau[s:e] = true_torques(m, mo.q, mo.dq, mo.ddq, chi) + rng.normal(0, 0.05, mo.q.shape)
    np.savez(path, times=t, positions=q, torques=tau)


def pipeline(path: Path) -> None:
    sys.path.insert(0, str(ROOT))
    t0 = time.perf_counter()
    from symoro_gen import load_model
    from symoro_gen.identification import accumulate, fit_ols, fit_tls
    from symoro_gen.identification.assemble import iter_observation_chunks
    from symoro_gen.preprocessing.trajectory import Trajectory

    m = load_model("lwr4")
    t_imp = time.perf_counter() - t0
    t0 = time.perf_counter()
    with np.load(path, mmap_mode="r") as z:
        tr = Trajectory(t=z["times"], q=z["positions"], tau=z["torques"], source=str(path))
        acc = accumulate(iter_observation_chunks(m, [tr]))
    t_asm = time.perf_counter() - t0
    t1 = time.perf_counter()
    ols = fit_ols(acc)
    t_ols = time.perf_counter() - t1
    t1 = time.perf_counter()
    fit_tls(acc)  # timed only
    t_tls = time.perf_counter() - t1
    total = time.perf_counter() - t0
    rss_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2
    truth = m.base_parameters(m.nominal_parameters())
    good = np.asarray(ols.rel_std_pct) < 1.0
    print(f"  samples {tr.n_samples:,} x 7 joints; rows of W after decimation: {ols.n_rows:,}; {len(ols.names)} parameters")
    print(f"  filter + decimate + assemble (streamed): {t_asm:.1f} s;  OLS {t_ols:.2f} s;  TLS {t_tls:.2f} s")
    print(f"  total {total:.1f} s (target <= 60 s; imports {t_imp:.1f} s not counted); peak RSS {rss_gb:.2f} GB (target <= 1.5 GB)")
    err = np.abs(np.asarray(ols.values) - truth)[good] / np.maximum(np.abs(truth[good]), 1e-9)
    print(f"  sanity: {good.sum()} parameters with %sigma < 1 recovered within {100 * err.max():.2f} % (OLS); "
          f"rel. err. norms {np.round(ols.rel_err, 4).tolist()}")
    print(f"[identification targets] {'met' if total <= 60 and rss_gb <= 1.5 else 'NOT met'}")


def main() -> int:
    if len(sys.argv) == 3:
        {"simulate": simulate, "pipeline": pipeline}[sys.argv[1]](Path(sys.argv[2]))
        return 0
    with tempfile.TemporaryDirectory(prefix="symoro_bench_") as td:
        path = Path(td) / "hour.npz"
        t = time.perf_counter()
        subprocess.run([sys.executable, __file__, "simulate", str(path)], check=True)
        print(f"[identification] {HOURS:g} h of 7-joint data at 1 kHz simulated in {time.perf_counter() - t:.0f} s "
              f"({path.stat().st_size / 1e6:.0f} MB, not timed)")
        env = dict(os.environ, OPENBLAS_NUM_THREADS=os.environ.get("OPENBLAS_NUM_THREADS", "1"))
        subprocess.run([sys.executable, __file__, "pipeline", str(path)], check=True, env=env)
    return 0


if __name__ == "__main__":
    sys.exit(main())
