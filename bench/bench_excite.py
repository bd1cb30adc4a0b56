"""Benchmark: optimised excitation vs the best of 50 random Fourier trajectories (issue 11 section 1).

For the KUKA LWR4 (7 joints) and the Staubli RX-90 (6 joints), with the ``[limits]`` of their robot
files: a Fourier design (5 harmonics, 10 s = one period, 100 Hz) optimised by ``symoro_gen.excite``
(IPOPT from seeded random starts) against 50 random Fourier trajectories of the same basis, limits and
duration, each scaled so that its tightest position, velocity or acceleration limit is reached. Prints
the unscaled condition number of the stacked base regressor of each, their ratio (target >= 5) and
the wall time of the optimisation. Torque limits are not imposed (the random ones would not be held
to them either).

    PYTHONPATH=. python bench/bench_excite.py [--robots lwr4 rx90] [--starts 3] [--max-iter 150]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from symoro_gen.excite import (
    FourierBasis,
    basis_eval,
    limits_of,
    optimise_excitation,
    output_times,
    random_trajectory,
    stacked_cond,
)
from symoro_gen.loader import model_for

TARGET_RATIO = 5.0


def run(name: str, *, harmonics: int, duration: float, rate: float, starts: int, max_iter: int, seed: int) -> dict:
    robot, model = model_for(name)
    lim = limits_of(robot)
    basis = FourierBasis(harmonics, 1.0 / duration)
    t = output_times(duration, rate)
    rng = np.random.default_rng(seed)
    rand = [stacked_cond(model, *basis_eval(basis, random_trajectory(basis, lim, rng, t), t)) for _ in range(50)]
    t0 = time.perf_counter()
    res = optimise_excitation(model, basis, lim, duration, rate=rate, starts=starts, seed=seed, max_iter=max_iter)
    wall = time.perf_counter() - t0
    # cond(W) >= max column norm / min column norm (sigma_max >= |w_i| >= sigma_min): how far the
    # limits let the columns' magnitudes be balanced bounds what any trajectory can reach
    W = np.asarray(model.regressor(res.q, res.dq, res.ddq)).reshape(-1, len(model.BASE_NAMES))
    norms = np.linalg.norm(W, axis=0)
    return {"column_bound": float(norms.max() / norms.min()), "smallest": model.BASE_NAMES[int(norms.argmin())],
            "largest": model.BASE_NAMES[int(norms.argmax())],"robot": name, "n": model.N_JOINTS, "nb": len(model.BASE_NAMES), "cond": res.cond,
            "random_best": min(rand), "random_median": float(np.median(rand)), "ratio": min(rand) / res.cond,
            "limits_ok": res.limits_ok, "wall": wall, "starts": res.starts}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", nargs="+", default=["lwr4", "rx90"])
    ap.add_argument("--harmonics", type=int, default=5)
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--rate", type=float, default=100.0)
    ap.add_argument("--starts", type=int, default=3)
    ap.add_argument("--max-iter", type=int, default=150)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    print(f"{'robot':6} {'n':>2} {'nb':>3} {'cond opt':>10} {'best of 50':>11} {'median':>9} {'ratio':>6} "
          f"{'limits':>6} {'wall [s]':>8}")
    ok = True
    for name in a.robots:
        r = run(name, harmonics=a.harmonics, duration=a.duration, rate=a.rate, starts=a.starts,
                max_iter=a.max_iter, seed=a.seed)
        ok &= r["limits_ok"]
        print(f"{r['robot']:6} {r['n']:>2} {r['nb']:>3} {r['cond']:>10.4g} {r['random_best']:>11.4g} "
              f"{r['random_median']:>9.4g} {r['ratio']:>6.2f} {r['limits_ok']!s:>6} {r['wall']:>8.1f}")
        print(f"        cond >= column-norm ratio {r['column_bound']:.4g} ({r['largest']} / {r['smallest']})")
        print("        starts: " + "; ".join(f"{s['cond_start']:.4g} -> {s['cond']:.4g} ({s['status']}, "
                                              f"{s['iterations']} it)" for s in r["starts"]))
    print(f"target: ratio >= {TARGET_RATIO:g} (best random cond / optimised cond)")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
