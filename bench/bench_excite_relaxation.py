"""How low can cond go if the trajectory were free to be ANY distribution of states within the limits?

The target asked for cond >= 5x below the best of 50 random Fourier trajectories. A trajectory's
stacked regressor gives ``W^T W / N = E[G(s)]``, ``G(s) = W(s)^T W(s)``, the mean over its samples
``s = (q, dq, ddq)``. Dropping the continuity in time (the relaxation), the smallest cond over
distributions of states within the position, velocity and acceleration limits is a linear SDP
(Boyd & Vandenberghe 2004, sect. 7.5), bracketed by ``research.excite_relaxation.relaxation_bracket``: column
generation (cvxpy + Clarabel on the states of weight > 1e-6 of the largest plus the new ones; new states
from fresh random states and multistart L-BFGS-B maximisation of the dual ratio ``tr(A G(s))/tr(B G(s))``
with CasADi gradients). Each round prints

* ``primal``: cond of the best distribution over the round's states (recomputed with numpy) - a
  rigorous UPPER bound on the relaxation's minimum;
* ``dual``: ``sqrt(tr A / (r tr B))`` with ``A, B`` the SDP's duals and ``r`` the largest ratio found -
  a LOWER bound on the cond of EVERY trajectory (any duration, any sampling, samples at rest included)
  if ``r`` is the global maximum of the ratio over the state box; found by sampling plus local
  maximisation, so rigorous only as far as that search is global.

With ``--stationary`` the distributions must also satisfy the stationarity moments of every closed
trajectory - periodic, or ending where it started: the Fourier designs, not the spline ones
(``research.excite_relaxation.stationarity_moments``: the mean of ``d/dt f(q, dq)`` is 0 for the test functions
``f``, held to ``--moment-tol`` of their scale), the first round seeded with the samples of
``--trajectories`` random Fourier trajectories (which satisfy them; also the default with ``--bandwidth``). ``--verify N`` re-prices
the final duals on N fresh random states of another seed plus 200 local searches
(``relaxation_verify``) and prints the lower end they still give.

At the end: the bracket ``[max(dual, cond_lower_bound), primal]`` (the rigorous bound of
``symoro_gen.excite.cond_lower_bound`` holds for distributions too: both of its halves are per-sample
arguments) against the excitation benchmark's target (best of the 50 random Fourier trajectories of
``bench/bench_excite.py``, 5 harmonics, 10 s, 100 Hz, seed 0, / 5).

    PYTHONPATH=. python bench/bench_excite_relaxation.py [--robot lwr4|rx90] [--atoms 400] [--rounds 60]
        [--budget SECONDS] [--tol 0.02] [--fresh 30000] [--starts 40] [--add 60] [--seed 0]
        [--stationary [--moment-tol 0.01] [--trajectories 10] [--degree 2|3]] [--rest [--kinetic energy|joint]
        [--features K [--cut-every R | --cut-at ROUND ...] [--dictionary 20000]]] [--braking] [--transit L] [--bandwidth K]
        [--perturb K] [--verify 300000 [--verify-starts 200]] [--save OUT.npz] [--start SAVED.npz]
    PYTHONPATH=. python bench/bench_excite_relaxation.py --robot R --rest [--moment-tol T] [--braking]
        --reverify SAVED.npz [--verify 400000] [--verify-starts 1000] [--seed S] [--perturb K]

``--rest`` adds the moments of every trajectory that starts and ends at rest (every design of ``excite``,
closed or not: ``research.excite_relaxation.RestMoments``, the rates of the momentum regressor and of every frame's
velocity, whose mean is 0 over such a trajectory), held to ``--moment-tol`` of their size; alone it bounds
every ``excite`` design, with ``--stationary`` the closed ones. The bench prints, for the best distribution
of every run, its largest rest moments and the first-moment columns in its motion and at rest (a relaxation
without ``--rest`` lets the arm fall on average, cancelling part of gravity in those columns).
``--kinetic`` adds test functions quadratic in ``dq`` to those moments (the kinetic-energy regressor's
entries, or every ``dq_j Y_p[j, b]``); ``--braking`` keeps every state to ``braking_speed`` (a joint at speed
must be able to stop before the end of its range); ``--save`` writes the best distribution and the duals.
Neither condition moves the floors (docs/excitation.md, "What no relaxation over distributions can do").
``--features K`` (with ``--rest``) is a cutting plane over the occupation-measure conditions: every
``--cut-every`` rounds the K random test functions (``FeatureMoments``: ``dq_j cos(omega.q + nu.dq + phi)``, which
vanish at rest) of a seeded dictionary that the best distribution violates most join the moments; the
``--trajectories`` then enter as whole-trajectory atoms (docs/excitation.md, "Random test functions").
``--save`` also writes the cuts and the trajectory atoms, which ``--start`` restores: a cut run continues where it
stopped, its cuts held from round 0. ``--reverify`` re-prices a saved run's lower-end duals on a search of its
own (more states, more local searches, another seed): a deeper search can only find larger dual ratios, so its
lower end is the more trustworthy one. ``--perturb K`` adds a search of another kind: ``K`` perturbations of every
atom of the saved distribution at 1-30 % of the box (the dual ratio is at its largest at the atoms of an optimal
distribution), with its own ``--verify-starts`` local searches; without ``--verify`` it runs without the fresh states.

``--transit L`` holds the ``TransitInequalities`` of ``L`` speed levels per joint: a joint's time at a speed is
bounded by its time at the speeds below it, since each burst must cross them at the acceleration limit at most and
can last only as long as the range allows (valid for every trajectory at rest at both ends and the 100-Hz samples of
every such design, of any duration, and every mixture of them); the bench then prints the friction ceilings under them
(``transit_friction_ceiling``) and, for every run, how far the best distribution is from meeting them.

``--degree 3`` adds the test functions of degree 3 (``research.excite_relaxation._degree3_tests``: 1456 more
conditions on the LWR4, 938 on the RX-90). ``--bandwidth K`` restricts the distributions to those of the
designs of the bench's Fourier basis (K harmonics, one period of 10 s, 100 Hz): ``E[ddq ddq^T] <= rho
E[dq dq^T]``, ``rho`` from ``research.excite_relaxation.basis_bandwidth`` - a bound for that design class only.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_excite import TARGET_RATIO, random_baseline, velocity_occupancy

from research.excite_relaxation import (
    PERTURB_SCALES,
    RelaxationBracket,
    RestMoments,
    TransitInequalities,
    basis_bandwidth,
    feature_dictionary,
    relaxation_bracket,
    relaxation_dual_bound,
    relaxation_rows,
    relaxation_verify,
    split_saved_atoms,
    stationarity_moment_names,
    stationarity_moments,
    stationarity_scales,
    transit_friction_ceiling,
)
from symoro_gen.excite import FourierBasis, cond_lower_bound, friction_ceiling, limits_of, output_times
from symoro_gen.loader import model_for


def _reverify(a, model, lim, robot) -> int:
    """``--reverify NPZ``: the lower end of a saved ``--rest`` run, re-priced on a search of its own (a deeper
    search can only find larger dual ratios, hence a lower, more trustworthy lower end)."""
    d = np.load(a.reverify)
    ids = d["cut_ids"] if "cut_ids" in d.files else np.zeros(0, int)
    run_seed = int(d["seed"]) if "seed" in d.files else 0  # the run's seed: its cuts' dictionary
    feats = feature_dictionary(lim, a.dictionary, run_seed).subset(ids) if len(ids) else None
    b = RelaxationBracket(0.0, float(d["upper"]), (), d["states"], d["signs"], d["weights"], d["A"], d["B"],
                          float(d["r"]), a.moment_tol, d["lam"], float(d["c0"]), closed=False,
                          rest=RestMoments(model, lim, robot), braking=a.braking, features=feats,
                          transit=TransitInequalities(lim, int(d["transit"])) if "transit" in d.files and int(d["transit"])
                          else None, eta=d["eta"] if "eta" in d.files and len(d["eta"]) else None)
    if len(b.lam) != len(b.rest.names) + (0 if feats is None else len(feats)):
        raise SystemExit(f"{a.reverify}: {len(b.lam)} moment multipliers, not those of a --rest run of {a.robot} "
                         f"with {len(ids)} random test functions")
    t0 = time.perf_counter()
    states = 0 if a.perturb and not a.verify else a.verify or 300_000
    r, bound = relaxation_verify(model, lim, b, states=states, starts=a.verify_starts, seed=a.seed, perturb=a.perturb)
    how = ", ".join(([f"{states} fresh states + {a.verify_starts} local searches"] if states else [])
                    + ([f"{a.perturb} perturbations of each atom x {len(PERTURB_SCALES)} scales + {a.verify_starts} "
                        "local searches"] if a.perturb else []))
    print(f"{a.robot}: {a.reverify}: saved r {b.r:.4f} (dual estimate {relaxation_dual_bound(b.A, b.B, b.r):.3f}); "
          f"{how} (seed {a.seed}): r {r:.4f}, "
          f"lower end {bound:.3f} ({time.perf_counter() - t0:.0f} s); upper end {b.upper:.3f}")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robot", default="lwr4")
    ap.add_argument("--atoms", type=int, default=400, help="random states of the first round")
    ap.add_argument("--rounds", type=int, default=60)
    ap.add_argument("--budget", type=float, default=1800.0, help="stop after the round that passes this many seconds")
    ap.add_argument("--tol", type=float, default=0.02, help="stop when primal / dual - 1 <= tol")
    ap.add_argument("--fresh", type=int, default=30_000, help="random states priced per round")
    ap.add_argument("--starts", type=int, default=40, help="L-BFGS-B starts per round (best random states; +1/4 random)")
    ap.add_argument("--add", type=int, default=60, help="best random states added per round")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--stationary", action="store_true", help="add the stationarity moments of trajectories")
    ap.add_argument("--moment-tol", type=float, default=0.01, help="|E[m]| <= tol x scale for each moment")
    ap.add_argument("--trajectories", type=int, default=None,
                    help="random Fourier trajectories whose samples join the first round (default 10 with --stationary)")
    ap.add_argument("--degree", type=int, choices=(2, 3), default=2, help="degree of the stationarity test functions")
    ap.add_argument("--rest", action="store_true",
                    help="add the moments of every trajectory at rest at both ends (RestMoments: the momentum "
                         "regressor's and the frame velocities' rates); alone: a bound on every excite design")
    ap.add_argument("--kinetic", choices=("energy", "joint"), default=None,
                    help="with --rest, also the rates of the kinetic-energy regressor's entries (energy) or of "
                         "dq_j times the momentum regressor's row j (joint): test functions quadratic in dq")
    ap.add_argument("--braking", action="store_true",
                    help="only states from which every joint can still stop before the end of its range "
                         "(braking_speed: dq^2 <= 2 ddq_max x the room left), as every design's samples")
    ap.add_argument("--bandwidth", type=int, default=None, metavar="K",
                    help="only the distributions of a Fourier design of K harmonics over 10 s at 100 Hz")
    ap.add_argument("--features", type=int, default=0, metavar="K",
                    help="with --rest, add each round the K random test functions (FeatureMoments, vanishing at rest) "
                         "the best distribution violates most: a cutting plane over the occupation-measure conditions")
    ap.add_argument("--dictionary", type=int, default=20_000, help="random test functions to choose them from")
    ap.add_argument("--cut-at", type=int, nargs="+", default=None, metavar="ROUND",
                    help="add the --features cuts after these rounds only (instead of --cut-every)")
    ap.add_argument("--start", default=None, metavar="NPZ",
                    help="the states of a --save'd best distribution join the first round (a warm start); its "
                         "trajectory atoms stay whole, and with --rest its random test functions are held from round 0 "
                         "(a cut run continues where it stopped)")
    ap.add_argument("--cut-every", type=int, default=1, metavar="R",
                    help="add the --features cuts every R rounds (the column generation converges in between)")
    ap.add_argument("--transit", type=int, default=0, metavar="L",
                    help="hold the TransitInequalities of L speed levels per joint (the time a burst of speed costs "
                         "at the speeds below it; see TransitInequalities for the designs it covers)")
    ap.add_argument("--verify", type=int, default=0, help="re-price the final duals on this many fresh states")
    ap.add_argument("--save", default=None, metavar="NPZ",
                    help="write the best distribution (states, signs, weights) and the duals of the lower end here")
    ap.add_argument("--verify-starts", type=int, default=200, metavar="K",
                    help="local searches of the verification (from the K best of its fresh states)")
    ap.add_argument("--perturb", type=int, default=0, metavar="K",
                    help="also price K random perturbations of every kept atom at each scale of PERTURB_SCALES each "
                         "round (local searches from the --starts best), and in the verification; with --reverify: "
                         "of every atom of the saved distribution (alone: without the fresh states unless --verify)")
    ap.add_argument("--reverify", default=None, metavar="NPZ",
                    help="only re-price the lower-end duals of a --save'd --rest run (give its --moment-tol and "
                         "--braking) on --verify fresh states and --verify-starts local searches, seed --seed")
    a = ap.parse_args(argv)
    robot, model = model_for(a.robot)
    lim = limits_of(robot)
    if a.reverify:
        return _reverify(a, model, lim, robot)
    print(f"{a.robot}: {model.N_JOINTS} joints, {len(model.BASE_NAMES)} base parameters; load "
          f"{os.getloadavg()[0]:.1f}", flush=True)

    def show(h):
        print(f"{a.robot} round {h.round}: {h.atoms} states ({h.kept} kept), primal cond {h.primal:.3f} (upper), "
              f"dual cond {h.dual:.3f} (lower estimate; r = {h.r:.4f}), SDP {h.sdp_seconds:.0f} s, "
              f"total {h.seconds:.0f} s, load {os.getloadavg()[0]:.1f}", flush=True)

    rho = None if a.bandwidth is None else basis_bandwidth(FourierBasis(a.bandwidth, 0.1), output_times(10.0, 100.0))
    if rho is not None:
        print(f"{a.robot}: bandwidth of a {a.bandwidth}-harmonic Fourier design over 10 s at 100 Hz: "
              f"E[ddq ddq^T] <= {rho:.4g} E[dq dq^T] ((rad/s)^2; (K w)^2 = {(a.bandwidth * 0.2 * np.pi) ** 2:.4g})")
    start = None if a.start is None else np.load(a.start)
    start_states = start_signs = None
    start_designs: list = []
    start_cuts = ()
    if start is not None:
        # a saved run: its states, its whole-trajectory atoms (the last blocks) and, with --rest, its cuts
        start_states, start_signs, start_designs = split_saved_atoms(
            start["states"], start["signs"], start["design_sizes"] if "design_sizes" in start.files else ())
        if a.rest and "cut_ids" in start.files:
            start_cuts = tuple(int(k) for k in start["cut_ids"])
        print(f"{a.robot}: warm start from {a.start}: {len(start_states)} states, {len(start_designs)} trajectory atoms, "
              f"{len(start_cuts)} random test functions held from round 0", flush=True)
    t0 = time.perf_counter()
    b = relaxation_bracket(model, lim, atoms=a.atoms, rounds=a.rounds, fresh=a.fresh, starts=a.starts, add=a.add,
                           tol=a.tol, time_budget=a.budget, seed=a.seed, stationary=a.stationary,
                           moment_tol=a.moment_tol, degree=a.degree, bandwidth=rho, rest=a.rest, robot=robot, kinetic=a.kinetic,
                           braking=a.braking, features=a.features, dictionary=a.dictionary,
                           cut_every=a.cut_every, cut_at=None if a.cut_at is None else tuple(a.cut_at),
                           extra_states=start_states, extra_signs=start_signs, extra_designs=start_designs,
                           cuts=start_cuts, transit=a.transit, perturb=a.perturb,
                           trajectories=(10 if a.stationary or a.rest or rho is not None else 0) if a.trajectories is None
                           else a.trajectories, progress=show)
    wall = time.perf_counter() - t0
    rand, _ = random_baseline(model, lim)
    target = min(rand) / TARGET_RATIO
    bound = cond_lower_bound(model, lim)
    lower, how = b.lower, "dual estimate"
    if a.verify:
        tv = time.perf_counter()
        r_v, lower_v = relaxation_verify(model, lim, b, states=a.verify, starts=a.verify_starts, seed=a.seed + 1,
                                         perturb=a.perturb)
        also = f" + {a.perturb} perturbations of each atom ({a.verify_starts} more local searches)" if a.perturb else ""
        print(f"{a.robot}: verification on {a.verify} fresh states + {a.verify_starts} local searches{also}: r {b.r:.4f} -> {r_v:.4f}, "
              f"dual estimate {b.lower:.3f} -> {lower_v:.3f} ({time.perf_counter() - tv:.0f} s)")
        lower, how = lower_v, "dual estimate, verified"
    if bound is not None and bound.bound > lower:
        lower, how = bound.bound, "rigorous cond_lower_bound (above the dual estimate)"
    kind = (f"stationary (moment tol {a.moment_tol:g}, degree {a.degree})" if a.stationary else
            "" if a.rest else "plain") + (", " if a.stationary and a.rest else "") + (
        f"rest (moment tol {a.moment_tol:g}{', kinetic ' + a.kinetic if a.kinetic else ''})" if a.rest else "") + (
        f", {a.bandwidth}-harmonic bandwidth" if rho is not None else "") + (", braking" if a.braking else "") + (
        f", transit ({a.transit} levels)" if a.transit else "") + (
        f", random test functions: {len(b.upper_features)} in the upper end's round, {len(b.features)} in the lower "
        f"end's" if b.features is not None and b.upper_features is not None else "")
    print(f"{a.robot} [{kind}]: dual estimate {b.lower:.3f}, primal {b.upper:.3f} ({len(b.rounds)} rounds, {wall:.0f} s; "
          f"the best distribution has {len(b.weights)} states of positive weight)")
    n = model.N_JOINTS
    p = b.weights / b.weights.sum()
    if a.save:
        np.savez(a.save, states=b.states, signs=b.signs, weights=p, lower=lower, upper=b.upper, A=b.A, B=b.B,
                 r=b.r, lam=np.zeros(0) if b.lam is None else b.lam, c0=b.c0, design_sizes=np.array(b.design_sizes, int),
                 cut_ids=np.zeros(0, int) if b.upper_features is None else np.asarray(b.upper_features.ids, int),
                 seed=a.seed, transit=a.transit, eta=np.zeros(0) if b.eta is None else b.eta)
        print(f"{a.robot}: best distribution and duals written to {a.save}")
    m = p @ (stationarity_moments(b.states[:, :n], b.states[:, n:2 * n], b.states[:, 2 * n:], degree=a.degree)
             / stationarity_scales(lim, a.degree))
    k = int(np.argmax(np.abs(m)))
    print(f"{a.robot}: the best distribution's stationarity moments of degree {a.degree} (0 for every closed trajectory): "
          f"largest |E[m]| / scale = {abs(m[k]):.3f}, {stationarity_moment_names(n, a.degree)[k]}; "
          f"{int(np.sum(np.abs(m) > 0.05))} of {len(m)} above 0.05")
    rest = b.rest if b.rest is not None else RestMoments(model, lim, robot)
    mean_acc = p @ rest.numpy(b.states[:, :n], b.states[:, n:2 * n], b.states[:, 2 * n:])
    m = mean_acc / rest.scale
    order = np.argsort(-np.abs(m))[:3]
    print(f"{a.robot}: the best distribution's rest moments (0 for every trajectory at rest at both ends): largest "
          f"|E[m]| / scale " + ", ".join(f"{abs(m[k]):.3f} ({rest.names[k]} = {mean_acc[k]:.3g})" for k in order) +
          f"; {int(np.sum(np.abs(m) > 0.05))} of {len(m)} above 0.05")
    tri = b.transit if b.transit is not None else TransitInequalities(lim, a.transit or 8)
    print(f"{a.robot}: the best distribution against the {len(tri)} transit inequalities of {tri.levels} speed levels "
          f"(<= 0 for every trajectory at rest at both ends): largest E[g] / (1 + kappa) {tri.worst(b.states, p):.3g}")
    pool = feature_dictionary(lim, a.dictionary, a.seed)  # the dictionary --features draws its cuts from
    v = np.abs(pool.weighted_sum(b.states, p) / pool.scale)
    print(f"{a.robot}: the best distribution against {len(pool)} random test functions that vanish at rest "
          f"(FeatureMoments, the --features dictionary of seed {a.seed}; 0 for every trajectory at rest at both ends): largest |E[m]| / scale "
          f"{v.max():.3f}; {int(np.sum(v > a.moment_tol))} above the moment tolerance {a.moment_tol:g}, "
          f"{int(np.sum(v > 0.01))} above 0.01")
    Wb = relaxation_rows(model, b.states, b.signs)
    ev = np.linalg.eigvalsh(np.einsum("k,kia,kib->ab", p, Wb, Wb))
    print(f"{a.robot}: the best distribution: sigma_max/sqrt(N) {np.sqrt(ev[-1]):.3g}, sigma_min/sqrt(N) "
          f"{np.sqrt(ev[0]):.3g}; per joint, weight at the velocity limit / creeping (|dq| >= 0.95 / <= 0.1 dq_max): "
          f"{velocity_occupancy(b.states[:, n:2 * n], lim.dq_max, p)}")
    fm = [i for i, c in enumerate(model.BASE_NAMES) if c[:2] in ("MX", "MY", "MZ")]
    if fm:  # the first moments: gravity alone at rest, gravity and the frames' accelerations in motion
        at_rest = np.hstack([b.states[:, :n], np.zeros((len(p), 2 * n))])
        Wr = relaxation_rows(model, at_rest, np.zeros((len(p), n)))
        print(f"{a.robot}: the best distribution's first-moment columns ({len(fm)}): sum of E[|column|^2] "
              f"{p @ (Wb[:, :, fm] ** 2).sum((1, 2)):.4g} in its motion, {p @ (Wr[:, :, fm] ** 2).sum((1, 2)):.4g} at rest "
              f"in its configurations (gravity alone)")
    if rho is not None:
        dq, ddq = b.states[:, n:2 * n], b.states[:, 2 * n:]
        slack = np.linalg.eigvalsh(rho * (dq.T * p) @ dq - (ddq.T * p) @ ddq)[0]
        print(f"{a.robot}: the best distribution's bandwidth LMI: smallest eigenvalue of rho E[dq dq^T] - E[ddq ddq^T] "
              f"= {slack:.3g} (>= 0 up to the solver's tolerance)")
    if bound is not None:
        print(f"rigorous bound over every trajectory: {bound.describe()}")
    if b.transit is not None:
        cap = np.sqrt(transit_friction_ceiling(lim, b.transit) / np.array([friction_ceiling(v) for v in lim.dq_max]))
        print(f"{a.robot}: friction ceilings under the transit inequalities, per joint, as a fraction of friction_ceiling's "
              f"(sqrt): " + " ".join(f"{c:.4f}" for c in cap))
    print(f"{a.robot}: relaxation's minimum in [{lower:.3f}, {b.upper:.3f}] (gap {b.upper / lower - 1:.1%}; lower end: "
          f"{how}; upper end: an explicit distribution of states)")
    scope = (f"{a.bandwidth}-harmonic Fourier design of 10 s" if rho is not None else
             "trajectory that ends where it started" if a.stationary else
             "trajectory at rest at both ends (every excite design)" if a.rest else "trajectory")
    verdict = (f"the target is BELOW the lower end: no {scope} reaches it" +
               (" (as far as the dual ratio's maximisation is global)" if how.startswith("dual") else "")
               if lower > target else
               "the target is ABOVE the relaxation's upper end: a distribution of states reaches it "
               f"(a {scope} still has to come close)" if b.upper <= target else
               "the target lies inside the bracket: not settled")
    print(f"target (best of 50 random Fourier / {TARGET_RATIO:g}) = {min(rand):.2f} / {TARGET_RATIO:g} = {target:.2f}: "
          f"{verdict}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
