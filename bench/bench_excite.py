"""Benchmark: optimised excitation vs the best of 50 random Fourier trajectories.

For the KUKA LWR4 (7 joints) and the Staubli RX-90 (6 joints), with the ``[limits]`` of their robot
files: a Fourier design (5 harmonics, 10 s = one period, 100 Hz) optimised by ``symoro_gen.excite``
(IPOPT from seeded random starts) against 50 random Fourier trajectories of the same basis, limits and
duration, each scaled so that its tightest position, velocity or acceleration limit is reached. Prints
the unscaled condition number of the stacked base regressor of each, their ratio (target >= 5) and
the wall time of the optimisation. Torque limits are not imposed (the random ones would not be held
to them either). It also prints ``symoro_gen.excite.cond_lower_bound``: a lower bound on the cond of ANY
trajectory within the velocity limits (sigma_max floored by a column set of constant squared norm per
sample, sigma_min capped by the friction columns), and where the target (best random / 5) and the
optimised cond lie relative to it.

    PYTHONPATH=. python bench/bench_excite.py [--robots lwr4 rx90] [--starts 3] [--max-iter 150] [--powers 8 64]
        [--kind fourier|spline] [--coefficients 60] [--structured N] [--refine N] [--samples N]
        [--embed M ...] [--embed-refine N] [--repeat K] [--duration S] [--ddq-scale F] [--baseline S ...]

``--kind spline`` optimises a cubic B-spline (``symoro_gen.excite.SplineBasis``) instead; the
baseline stays the 50 random Fourier trajectories. ``--embed 117 231`` then represents the spline optimum
exactly in splines of more control points (each level's knot intervals a multiple of the previous one's:
knot insertion) and refines it there (``--embed-refine`` SDPs each): does more freedom move the optimum?
``--repeat K`` also compares the optimised design run K times back to back with the random Fourier
trajectories of period K x duration (repeating a run that ends where it started leaves its cond unchanged;
a spline design, which ends elsewhere, is run forward and backward in turn; the random baseline of a
longer period is slower). ``--baseline 5 10 20 30 60`` prints only the random baseline (best, median,
target) at each duration. ``--refine N`` follows each start's IPOPT result with at most N iterations of
``symoro_gen.excite.refine_excitation`` (sequential SDP on the true cond) and prints the cond before and
after it. ``--ddq-scale F`` gives the optimised design F times the robot's acceleration limits (the random
baseline and the target keep the robot's): does continuity in time - the time a joint needs to change its
velocity - hold the designs back?
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from symoro_gen.excite import (
    FourierBasis,
    SplineBasis,
    basis_eval,
    check_limits,
    cond_lower_bound,
    dense_times,
    limits_of,
    optimise_excitation,
    output_times,
    random_trajectory,
    refine_excitation,
    stacked_cond,
)
from symoro_gen.loader import model_for

TARGET_RATIO = 5.0


def velocity_occupancy(dq: np.ndarray, dq_max: np.ndarray, weights: np.ndarray | None = None) -> str:
    """Per joint, the fraction of the samples (or of the weight) at the velocity limit (|dq| >= 0.95 dq_max)
    and creeping (|dq| <= 0.1 dq_max): the friction columns' best distribution has about 0.3 at the limit and
    the rest creeping, nothing in between (``symoro_gen.excite.friction_ceiling``)."""
    w = np.full(len(dq), 1.0 / len(dq)) if weights is None else weights / weights.sum()
    r = np.abs(dq) / dq_max
    at, creep = w @ (r >= 0.95), w @ (r <= 0.1)
    return " ".join(f"{a:.2f}/{c:.2f}" for a, c in zip(at, creep))


def random_baseline(model, lim, *, harmonics: int = 5, duration: float = 10.0, rate: float = 100.0, seed: int = 0,
                    count: int = 50) -> tuple[list[float], list[float]]:
    """cond and sigma_max / sqrt(N) of ``count`` random Fourier trajectories (``harmonics``, one period of
    ``duration`` s sampled at ``rate``, seeded), each scaled per joint to touch its tightest limit on the
    10x denser resampling the optimised designs are checked on (so that both hold the same limits between
    samples too): the issue-11 baseline (the target is the best of them / 5)."""
    rand, rand_smax = [], []
    for q, dq, ddq in random_designs(lim, harmonics=harmonics, duration=duration, rate=rate, seed=seed, count=count):
        Wr = np.asarray(model.regressor(q, dq, ddq)).reshape(-1, len(model.BASE_NAMES))
        sr = np.linalg.svd(Wr, compute_uv=False)
        rand.append(float(sr[0] / sr[-1]))
        rand_smax.append(float(sr[0] / np.sqrt(len(q))))
    return rand, rand_smax


def random_designs(lim, *, harmonics: int = 5, duration: float = 10.0, rate: float = 100.0, seed: int = 0,
                   count: int = 50):
    """``(q, dq, ddq)`` at ``rate`` of the baseline's ``count`` random Fourier trajectories (see
    :func:`random_baseline`), one at a time."""
    basis = FourierBasis(harmonics, 1.0 / duration)
    t = output_times(duration, rate)
    t_dense = dense_times(t, duration, basis)
    rng = np.random.default_rng(seed)
    for _ in range(count):
        X = random_trajectory(basis, lim, rng, t_dense)
        assert check_limits(lim, *basis_eval(basis, X, t_dense))["ok"]
        yield basis_eval(basis, X, t)


def run(name: str, *, harmonics: int, duration: float, rate: float, starts: int, max_iter: int, seed: int,
        pool: int | None, powers=None, kind: str = "fourier", coefficients: int = 60, structured: int = 0,
        refine: int = 0, samples: int | None = None, embed=(), embed_refine: int = 30, repeat: int = 1,
        jobs: int = 1, ddq_scale: float = 1.0) -> dict:
    robot, model = model_for(name)
    lim = limits_of(robot)
    lim_opt = dataclasses.replace(lim, ddq_max=lim.ddq_max * ddq_scale)  # the design's; the baseline keeps lim
    basis = FourierBasis(harmonics, 1.0 / duration)
    rand, rand_smax = random_baseline(model, lim, harmonics=harmonics, duration=duration, rate=rate, seed=seed)
    t0 = time.perf_counter()
    design = basis if kind == "fourier" else SplineBasis(coefficients, duration)
    res = optimise_excitation(model, design, lim_opt, duration, rate=rate, starts=starts, seed=seed + 1, max_iter=max_iter,
                              pool=pool, powers=powers, structured=structured, refine=refine, samples=samples,
                              jobs=jobs)
    q, dq, ddq, cond = res.q, res.dq, res.ddq, res.cond
    embedded = []
    X = res.X
    t_out = output_times(duration, rate)
    for M in embed:
        if kind != "spline":
            raise SystemExit("--embed needs --kind spline")
        if (M - 3) % (design.M - 3):
            raise SystemExit(f"--embed {M}: {M - 3} knot intervals are not a multiple of {design.M - 3}")
        fine = SplineBasis(M, duration)
        td = np.linspace(0.0, duration, 20 * (M - 3) + 1)
        X_f = np.linalg.lstsq(fine.matrices(td)[0], design.matrices(td)[0] @ X, rcond=None)[0]  # exact: knot insertion
        c_in = stacked_cond(model, *basis_eval(fine, X_f, t_out))
        te = time.perf_counter()
        X_r, hist = refine_excitation(model, fine, lim_opt, X_f, t_out, t_out, iterations=embed_refine,
                                      check_times=dense_times(t_out, duration, fine))
        c_out = stacked_cond(model, *basis_eval(fine, X_r, t_out))
        embedded.append({"coefficients": M, "cond_in": c_in, "cond": c_out, "sdps": len(hist) - 1,
                         "time": time.perf_counter() - te})
        design, X = fine, X_r
        if c_out < cond:
            q, dq, ddq = basis_eval(fine, X_r, t_out)
            cond = c_out
    wall = time.perf_counter() - t0
    # the embedded design is held to the limits as optimise_excitation holds its result: on the output samples
    # and on the 10x denser resampling with the knots
    limits_ok = res.limits_ok and (not embedded or all(
        check_limits(lim_opt, *basis_eval(design, X, tt))["ok"] for tt in (t_out, dense_times(t_out, duration, design))))
    repeated = None
    if repeat > 1:
        # the design run `repeat` times back to back, at rest at every junction. A design that ends where it
        # started (Fourier) is repeated as it is: its samples repeat, its cond is that of one run. One that
        # ends elsewhere (a spline) is run forward, then backward (q(T - t): dq -> -dq, ddq unchanged), and so
        # on, so that each run starts where the previous one stopped. Against random Fourier trajectories of
        # period repeat x duration.
        closed = bool(np.abs(q[-1] - q[0]).max() <= 1e-9)
        runs = [(q, dq, ddq)]
        for k in range(1, repeat):
            forward = closed or k % 2 == 0
            runs.append((q[1:], dq[1:], ddq[1:]) if forward else (q[::-1][1:], -dq[::-1][1:], ddq[::-1][1:]))
        qr, dqr, ddqr = (np.vstack(c) for c in zip(*runs))
        c_rep = stacked_cond(model, qr, dqr, ddqr)
        rand_long, _ = random_baseline(model, lim, harmonics=harmonics, duration=repeat * duration, rate=rate, seed=seed)
        repeated = {"repeat": repeat, "duration": repeat * duration, "cond": c_rep, "closed": closed,
                    "random_best": min(rand_long), "ratio": min(rand_long) / c_rep}
    W = np.asarray(model.regressor(q, dq, ddq)).reshape(-1, len(model.BASE_NAMES))
    sv = np.linalg.svd(W, compute_uv=False)
    N = W.shape[0] / model.N_JOINTS
    bound = cond_lower_bound(model, lim)
    return {"robot": name, "n": model.N_JOINTS, "nb": len(model.BASE_NAMES), "cond": cond,
            "random_best": min(rand), "random_median": float(np.median(rand)), "ratio": min(rand) / cond,
            "limits_ok": limits_ok, "embedded": embedded, "repeated": repeated, "wall": wall, "starts": res.starts, "bound": bound,
            "smax": float(sv[0] / np.sqrt(N)), "smin": float(sv[-1] / np.sqrt(N)), "random_smax_min": min(rand_smax),
            "occupancy": velocity_occupancy(dq, lim.dq_max)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", nargs="+", default=["lwr4", "rx90"])
    ap.add_argument("--harmonics", type=int, default=5)
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--rate", type=float, default=100.0)
    ap.add_argument("--starts", type=int, default=3)
    ap.add_argument("--max-iter", type=int, default=150)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--pool", type=int, default=None, help="random designs the IPOPT starts are chosen from")
    ap.add_argument("--jobs", type=int, default=1,
                    help="the starts in this many processes (0: one per CPU); same design, shorter wall time")
    ap.add_argument("--powers", type=int, nargs="+", default=None,
                    help="continuation powers of the cond criterion (default symoro_gen.excite.COND_POWERS)")
    ap.add_argument("--kind", choices=("fourier", "spline"), default="fourier",
                    help="kind of the optimised trajectory (the random baseline is always the Fourier one)")
    ap.add_argument("--coefficients", type=int, default=60, help="spline control points per joint")
    ap.add_argument("--structured", type=int, default=0,
                    help="designs alternating slow motion and bursts at the velocity limit added to the pool")
    ap.add_argument("--samples", type=int, default=None, help="samples of the IPOPT criterion (default: library's)")
    ap.add_argument("--embed", type=int, nargs="*", default=[],
                    help="spline: refine the optimum again in splines of these many control points (knot insertion)")
    ap.add_argument("--embed-refine", type=int, default=30, help="SDP iterations at each --embed level")
    ap.add_argument("--refine", type=int, default=0,
                    help="sequential-SDP iterations on the true cond after each start's IPOPT result (0: none)")
    ap.add_argument("--repeat", type=int, default=1, metavar="K",
                    help="also compare the optimised design run K times back to back (K x duration) with the random "
                         "Fourier trajectories of period K x duration")
    ap.add_argument("--ddq-scale", type=float, default=1.0, metavar="F",
                    help="the optimised design's acceleration limits times F (the random baseline keeps the robot's): "
                         "does continuity in time hold the designs back?")
    ap.add_argument("--baseline", type=float, nargs="+", default=None, metavar="SECONDS",
                    help="only the 50 random Fourier trajectories (period = duration) at each of these durations: "
                         "best, median and the target (best / 5); no optimisation")
    a = ap.parse_args(argv)
    if a.baseline:
        print(f"{'robot':6} {'duration':>8} {'best of 50':>11} {'median':>9} {'target':>7}")
        for name in a.robots:
            robot, model = model_for(name)
            lim = limits_of(robot)
            for T in a.baseline:
                rand, _ = random_baseline(model, lim, harmonics=a.harmonics, duration=T, rate=a.rate, seed=a.seed)
                print(f"{name:6} {T:>8g} {min(rand):>11.4g} {float(np.median(rand)):>9.4g} "
                      f"{min(rand) / TARGET_RATIO:>7.4g}", flush=True)
        return 0
    print(f"{'robot':6} {'n':>2} {'nb':>3} {'cond opt':>10} {'best of 50':>11} {'median':>9} {'ratio':>6} "
          f"{'limits':>6} {'wall [s]':>8}")
    ok = True
    for name in a.robots:
        r = run(name, harmonics=a.harmonics, duration=a.duration, rate=a.rate, starts=a.starts,
                max_iter=a.max_iter, seed=a.seed, pool=a.pool, powers=a.powers, kind=a.kind,
                coefficients=a.coefficients, structured=a.structured, refine=a.refine, samples=a.samples,
                embed=a.embed, embed_refine=a.embed_refine, repeat=a.repeat, jobs=a.jobs, ddq_scale=a.ddq_scale)
        ok &= r["limits_ok"]
        print(f"{r['robot']:6} {r['n']:>2} {r['nb']:>3} {r['cond']:>10.4g} {r['random_best']:>11.4g} "
              f"{r['random_median']:>9.4g} {r['ratio']:>6.2f} {r['limits_ok']!s:>6} {r['wall']:>8.1f}")
        bd = r["bound"]
        need = r["random_best"] / TARGET_RATIO
        print(f"        {bd.describe()}")
        print(f"        target cond <= {need:.4g} (best random / {TARGET_RATIO:g}) = {need / bd.bound:.3g} x the bound: "
              f"{'not excluded by' if need >= bd.bound else 'UNREACHABLE by'} the bound; optimised = "
              f"{r['cond'] / bd.bound:.3g} x the bound (sigma_max/sqrt(N) {r['smax']:.3g} >= {np.sqrt(bd.smax2):.3g}, "
              f"sigma_min/sqrt(N) {r['smin']:.3g} <= {np.sqrt(bd.smin2):.3g}; smallest sigma_max/sqrt(N) of the 50 "
              f"random: {r['random_smax_min']:.3g})")
        print(f"        per joint, fraction of the samples at the velocity limit / creeping (|dq| >= 0.95 / <= 0.1 "
              f"dq_max): {r['occupancy']}")
        print("        starts: " + "; ".join(f"{s['cond_start']:.4g} -> "
                                              + " -> ".join(f"{c:.4g}" for c in s.get("cond_stages", [s["cond"]]))
                                              + f" (p = {s.get('powers')}, {s['status']}, {s['iterations']} it)"
                                              + (f" -> SDP refinement {s['cond']:.4g} ({s['refine_sdps']} SDPs, "
                                                 f"{s['refine_accepted']} steps accepted, {s['refine_time']:.0f} s)"
                                                 if "refine_sdps" in s else "")
                                              for s in r["starts"]))
        if r["repeated"]:
            rp = r["repeated"]
            how = "times" if rp["closed"] else "times, forward and backward in turn (it ends elsewhere than it starts)"
            print(f"        run {rp['repeat']} {how} ({rp['duration']:g} s): cond {rp['cond']:.4g}; best of 50 random Fourier "
                  f"of period {rp['duration']:g} s: {rp['random_best']:.4g}; ratio {rp['ratio']:.2f} (a random Fourier "
                  f"trajectory of period {a.duration:g} s run {rp['repeat']} times keeps its cond: ratio {r['ratio']:.2f})")
        for e in r["embedded"]:
            print(f"        embedded in {e['coefficients']} control points: {e['cond_in']:.4g} -> {e['cond']:.4g} "
                  f"({e['sdps']} SDPs, {e['time']:.0f} s)")
    print(f"target: ratio >= {TARGET_RATIO:g} (best random cond / optimised cond)")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
