"""Do the acceleration limits hold the excitation designs back? (the 5x target)

The relaxation over distributions of states (``bench/bench_excite_relaxation.py``) ignores continuity in
time; one way a trajectory pays for continuity is the time a joint needs to change its velocity, set by the
acceleration limits. This bench takes the spline optimum of ``bench/bench_excite.py --kind spline
--coefficients 60 --structured 10 --starts 1 --pool 10 --max-iter 300 --refine 20`` (the robot's limits),
then continues the SDP refinement (``symoro_gen.excite.refine_excitation``) from it twice, ``--sdps`` SDPs
each: once with the acceleration limits multiplied by ``--scale`` (the position and velocity limits kept),
once with the robot's own. If the acceleration limits held the optimum, the first would go clearly lower.
It prints the cond of each and the peak acceleration of the first against the robot's limits.

    PYTHONPATH=. python bench/bench_excite_accel.py [--robot rx90|lwr4] [--scale 100] [--sdps 30]
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from symoro_gen.excite import (
    SplineBasis,
    basis_eval,
    check_limits,
    limits_of,
    optimise_excitation,
    output_times,
    refine_excitation,
    stacked_cond,
)
from symoro_gen.loader import model_for


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robot", default="rx90")
    ap.add_argument("--scale", type=float, default=100.0, help="factor on the acceleration limits")
    ap.add_argument("--sdps", type=int, default=30, help="SDP iterations of each continued refinement")
    a = ap.parse_args(argv)
    robot, model = model_for(a.robot)
    lim = limits_of(robot)
    basis, t = SplineBasis(60, 10.0), output_times(10.0, 100.0)
    t0 = time.perf_counter()
    res = optimise_excitation(model, basis, lim, 10.0, rate=100.0, starts=1, seed=1, max_iter=300, pool=10,
                              structured=10, refine=20)
    print(f"{a.robot}: spline optimum {res.cond:.4g} (robot's limits; peak acceleration use "
          f"{max(res.usage['ddq']):.3f}; {time.perf_counter() - t0:.0f} s)", flush=True)
    for label, L in ((f"acceleration limits x {a.scale:g}", dataclasses.replace(lim, ddq_max=lim.ddq_max * a.scale)),
                     ("the robot's limits", lim)):
        t1 = time.perf_counter()
        X, hist = refine_excitation(model, basis, L, res.X, t, t, iterations=a.sdps)
        q, dq, ddq = basis_eval(basis, X, t)
        use = max(check_limits(lim, q, dq, ddq)["usage"]["ddq"])
        print(f"  continued with {label}: cond {stacked_cond(model, q, dq, ddq):.4g} after {len(hist) - 1} SDPs "
              f"({sum(bool(h.get('accepted')) for h in hist)} accepted, {time.perf_counter() - t1:.0f} s); peak "
              f"acceleration {use:.2f} x the robot's limits", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
