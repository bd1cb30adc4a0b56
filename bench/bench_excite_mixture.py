"""Benchmark: what MIXTURES of 10-s designs reach (docs/excitation.md, "Why no
relaxation over distributions can settle the target").

Every condition the relaxations of ``research.excite_relaxation`` hold for every design (a moment of the
distribution of states within a tolerance of zero, a set the states keep to) holds for every mixture of
designs too: design 1 run for a fraction ``p1`` of the time, design 2 for ``p2``, ... So none of them can
bound the cond of a single design above the best mixture's. This bench measures the best mixture
(``mixture_cond``: an SDP over the time fractions) of

* the random Fourier trajectories of the excitation benchmark's baseline (5 harmonics, 10 s, each scaled to touch its
  tightest limit on the 10x denser grid; seed 0: the first 50 are the bench's baseline), ``--random``;
* ``--optimised K`` spline designs optimised from K seeds (one start each: 60 control points, structured
  starts, IPOPT, SDP refinement; ``--max-iter``, ``--refine``), alone and with their time-reversed runs
  (``q(T - t)``: the same cond, the friction columns' signs flipped),

against the best single design of each set and the target (best of the first 50 random / 5). ``--price R``
then runs R rounds of column generation over designs: the duals ``A, B`` of the mixture SDP price a new
design (IPOPT on ``-log tr(A M) + log tr(B M)`` within the limits, through the generated CasADi model, from
the pool design of the largest ratio and from a structured start), which joins the pool - how far mixtures
of (locally priced) designs go.

``--pieces S`` prices short rest-to-rest *pieces* instead: cubic splines of ``--points`` control points over
``S`` seconds, each at rest at both ends and anywhere within the limits; ``--init`` random ones (each
structured or a random walk, at even odds), then ``--price R`` rounds, each adding ``--per-round`` pieces priced by IPOPT
(half from the pool pieces of the largest dual ratio, half from fresh random ones). A mixture of pieces is a
long experiment cut at its rests (the moves between pieces left out). ``--equal K ...`` then asks what ``K``
*distinct* pieces run for equal times reach (``K x S`` seconds of motion: the best set found by exchanges
from the mixture's ``K`` heaviest pieces), which the mixture bounds from below.

    PYTHONPATH=. python bench/bench_excite_mixture.py --robots rx90 --random --pieces 2 --price 40 --equal 5 10 20 40

    PYTHONPATH=. python bench/bench_excite_mixture.py --robots lwr4 rx90 --random 50 400 --optimised 8
    PYTHONPATH=. python bench/bench_excite_mixture.py --robots rx90 --random --optimised 8 --price 10
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_excite import random_designs

from research.excite_relaxation import mixture_cond, mixture_duals
from symoro_gen import excite as E
from symoro_gen.excite import (
    SplineBasis,
    basis_eval,
    friction_trajectory,
    limits_of,
    optimise_excitation,
    output_times,
    random_trajectory,
)
from symoro_gen.loader import model_for

TARGET_RATIO = 5.0


def information(model, q, dq, ddq) -> np.ndarray:
    """``W^T W / N`` of the base regressor stacked over the samples."""
    W = np.asarray(model.regressor(q, dq, ddq)).reshape(-1, len(model.BASE_NAMES))
    return W.T @ W / len(q)


def cond_of(M: np.ndarray) -> float:
    ev = np.linalg.eigvalsh(M)
    return float(np.sqrt(ev[-1] / ev[0])) if ev[0] > 0 else float("inf")


def random_matrices(model, lim, count: int, seed: int = 0) -> np.ndarray:
    """The information matrices of ``count`` random Fourier trajectories, drawn as the baseline of
    ``bench_excite.py`` draws them (same seed: the same first trajectories)."""
    return np.array([information(model, *qdq) for qdq in random_designs(lim, seed=seed, count=count)])


def _ratio_solver(model, lim, basis, max_iter: int, t_obj: np.ndarray, t_con: np.ndarray, dense: np.ndarray):
    """IPOPT on ``-log tr(A M) + log tr(B M)`` of the design ``basis`` (``M`` on ``t_obj``; the limits with a 1 %
    margin on ``t_con``): ``solve(X0, A, B) -> X``, checked on ``dense`` and scaled into the limits if need be."""
    import casadi as ca

    nb = len(model.BASE_NAMES)
    nlp, bounds = E.build_nlp(model, basis, lim, t_obj, t_con, "logdet", None, 0.01)  # its constraints
    x = nlp["x"]
    M = E.design_information(model, basis, x, t_obj)
    Ap, Bp = ca.MX.sym("A", nb, nb), ca.MX.sym("B", nb, nb)
    opts = {"ipopt.print_level": 0, "print_time": False, "ipopt.max_iter": int(max_iter), "ipopt.tol": 1e-6,
            "ipopt.hessian_approximation": "limited-memory", "ipopt.sb": "yes"}
    solver = ca.nlpsol("price", "ipopt", {"x": x, "p": ca.vertcat(ca.vec(Ap), ca.vec(Bp)), "g": nlp["g"],
                                          "f": -ca.log(ca.trace(Ap @ M)) + ca.log(ca.trace(Bp @ M))}, opts)

    def solve(X0, A, B):
        sol = solver(x0=X0.T.reshape(-1), p=np.concatenate([A.T.reshape(-1), B.T.reshape(-1)]),
                     lbg=bounds["lbg"], ubg=bounds["ubg"])
        Xn = np.asarray(sol["x"]).reshape(lim.n, basis.m).T
        return Xn if E.inside_limits(basis, lim, Xn, dense) else E.scale_into(basis, lim, Xn, dense)

    return solve


def pricer(model, lim, basis, max_iter: int):
    """IPOPT on the dual ratio of a mixture SDP: ``solve(X0, A, B) -> X`` within the limits."""
    return _ratio_solver(model, lim, basis, max_iter, np.linspace(0, 10, 200), np.linspace(0, 10, 400),
                         E.dense_times(output_times(10.0, 100.0), 10.0, basis))


def piece_pricer(model, lim, basis, max_iter: int):
    """IPOPT on the dual ratio ``tr(A M) / tr(B M)`` of a mixture SDP over pieces of the spline ``basis`` (its own
    duration): ``solve(X0, A, B) -> X`` within the limits (1 % margin in the NLP; checked, and scaled into them
    if need be, on the dense grid), ``info(X) -> W^T W / N`` at 100 Hz, the NLP's constraint grid and the
    dense grid."""
    D = basis.duration
    t_con, t_out = np.linspace(0, D, int(80 * D) + 1), np.arange(0, D + 1e-9, 0.01)
    dense = E.dense_times(t_out, D, basis)
    solve = _ratio_solver(model, lim, basis, max_iter, np.linspace(0, D, int(40 * D) + 1), t_con, dense)

    def info(X):
        return information(model, *basis_eval(basis, X, t_out))

    return solve, info, t_con, dense


def best_equal_set(Ms: np.ndarray, K: int, start=None) -> tuple[float, list[int]]:
    """The ``K`` distinct designs of ``Ms`` (``(k, nb, nb)``, per-sample information matrices) whose equal-time
    mixture has the smallest cond found: from ``start`` (default the first ``K``), exchanges of one design for
    another while one lowers cond (a local search; the mixture SDP bounds it from below)."""
    sel = list(range(K)) if start is None else [int(i) for i in start]
    best = cond_of(Ms[sel].mean(0))
    improved = True
    while improved:
        improved = False
        for slot in range(K):
            for j in range(len(Ms)):
                if j in sel:
                    continue
                trial = sel.copy()
                trial[slot] = j
                c = cond_of(Ms[trial].mean(0))
                if c < best - 1e-9:
                    best, sel, improved = c, trial, True
    return best, sel


def price_pieces(model, lim, a) -> None:
    """``--pieces``: column generation over short rest-to-rest pieces, then ``--equal`` (see the module doc)."""
    basis = SplineBasis(a.points, a.pieces)
    solve, info, t_con, dense = piece_pricer(model, lim, basis, a.max_iter)
    rng = np.random.default_rng(a.seed)

    def fresh():  # scaled into the limits on the dense grid, as the priced pieces are checked
        X = (friction_trajectory(basis, lim.shrunk(0.01), rng, t_con, a.pieces) if rng.random() < 0.5
             else random_trajectory(basis, lim, rng, t_con))
        return X if E.inside_limits(basis, lim, X, dense) else E.scale_into(basis, lim, X, dense)

    designs = [fresh() for _ in range(a.init)]
    Ms = [info(X) for X in designs]
    t0 = time.perf_counter()
    for rd in range(a.price + 1):
        c, p, A, B = mixture_duals(np.array(Ms))
        ratio = np.array([np.trace(A @ Mi) / np.trace(B @ Mi) for Mi in Ms])
        print(f"{model.ROBOT}: {a.pieces:g}-s pieces, round {rd}: {len(Ms)} pieces, best mixture {c:.3f} "
              f"({int(np.sum(p > 1e-3))} above 0.1 % of the time; {time.perf_counter() - t0:.0f} s)", flush=True)
        if rd == a.price:
            break
        order = np.argsort(-ratio)
        starts = [designs[i] for i in order[:a.per_round // 2]] + [fresh() for _ in range(a.per_round - a.per_round // 2)]
        for X0 in starts:
            Xn = solve(X0, A, B)
            designs.append(Xn)
            Ms.append(info(Xn))
    if a.save:
        np.savez(a.save, designs=np.array(designs), Ms=np.array(Ms), p=p)
    heavy = np.argsort(-p)
    for K in a.equal:
        ce, sel = best_equal_set(np.array(Ms), K, heavy[:K])
        print(f"{model.ROBOT}: {K} distinct {a.pieces:g}-s pieces for equal times ({K * a.pieces:g} s of motion): "
              f"cond {ce:.3f} (the mixture of all: {c:.3f})", flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robots", nargs="+", default=["lwr4", "rx90"])
    ap.add_argument("--random", nargs="*", type=int, default=[50, 400], help="sizes of the random sets (seed 0)")
    ap.add_argument("--optimised", type=int, default=0, metavar="K", help="optimised spline designs (seeds 1..K)")
    ap.add_argument("--max-iter", type=int, default=150)
    ap.add_argument("--refine", type=int, default=10)
    ap.add_argument("--price", type=int, default=0, metavar="R", help="rounds of column generation over designs")
    ap.add_argument("--pieces", type=float, default=None, metavar="S",
                    help="price rest-to-rest pieces of S seconds instead of 10-s designs")
    ap.add_argument("--points", type=int, default=14, help="--pieces: spline control points per piece")
    ap.add_argument("--init", type=int, default=40, help="--pieces: random pieces to start from")
    ap.add_argument("--per-round", type=int, default=6, help="--pieces: pieces priced per round")
    ap.add_argument("--equal", type=int, nargs="*", default=[], metavar="K",
                    help="--pieces: the best K distinct pieces for equal times")
    ap.add_argument("--seed", type=int, default=0, help="--pieces: seed of the random pieces")
    ap.add_argument("--save", default=None, metavar="NPZ", help="--pieces: save the pieces and their matrices")
    a = ap.parse_args(argv)
    for name in a.robots:
        robot, model = model_for(name)
        lim = limits_of(robot)
        base = random_matrices(model, lim, 50)
        target = min(cond_of(M) for M in base) / TARGET_RATIO
        print(f"{name}: target (best of the 50 random / {TARGET_RATIO:g}) = {target:.2f}", flush=True)
        if a.pieces is not None:
            price_pieces(model, lim, a)
        for count in a.random:
            t0 = time.perf_counter()
            Ms = base[:count] if count <= 50 else random_matrices(model, lim, count)
            c, p = mixture_cond(Ms)
            print(f"{name}: {count} random Fourier designs: best single {min(cond_of(M) for M in Ms):.2f}, "
                  f"best mixture {c:.2f} ({int(np.sum(p > 1e-3))} designs above 0.1 % of the time, largest "
                  f"share {p.max():.2f}; {time.perf_counter() - t0:.0f} s)", flush=True)
        if a.optimised:
            fwd, both, designs = [], [], []
            basis, t = SplineBasis(60, 10.0), output_times(10.0, 100.0)
            for s in range(1, a.optimised + 1):
                t0 = time.perf_counter()
                res = optimise_excitation(model, SplineBasis(60, 10.0), lim, 10.0, rate=100.0, starts=1, seed=s,
                                          max_iter=a.max_iter, pool=10, structured=10, refine=a.refine, jobs=1)
                M = information(model, res.q, res.dq, res.ddq)
                Mr = information(model, res.q[::-1], -res.dq[::-1], res.ddq[::-1])
                fwd.append(M)
                both += [M, Mr]
                designs.append(res.X)
                print(f"{name}: optimised design, seed {s}: cond {res.cond:.2f} (limits held: {res.limits_ok}; "
                      f"{time.perf_counter() - t0:.0f} s)", flush=True)
            c, p = mixture_cond(np.array(fwd))
            c2, _ = mixture_cond(np.array(both))
            print(f"{name}: {a.optimised} optimised designs: best single {min(cond_of(M) for M in fwd):.2f}, best "
                  f"mixture {c:.2f} (shares {', '.join(f'{x:.2f}' for x in np.sort(p)[::-1] if x > 1e-3)}), "
                  f"with their time-reversed runs {c2:.2f}; target {target:.2f}", flush=True)
            if a.price:
                solve, rng, t0 = pricer(model, lim, basis, a.max_iter), np.random.default_rng(7), time.perf_counter()
                for rd in range(a.price + 1):
                    c, p, A, B = mixture_duals(np.array(fwd))
                    ratio = [float(np.trace(A @ M) / np.trace(B @ M)) for M in fwd]
                    print(f"{name}: pricing round {rd}: {len(fwd)} designs, best mixture {c:.3f} "
                          f"({time.perf_counter() - t0:.0f} s)", flush=True)
                    if rd == a.price:
                        break
                    for X0 in (designs[int(np.argmax(ratio))],
                               friction_trajectory(basis, lim.shrunk(0.01), rng, np.linspace(0, 10, 400), 10.0)):
                        Xn = solve(X0, A, B)
                        designs.append(Xn)
                        fwd.append(information(model, *basis_eval(basis, Xn, t)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
