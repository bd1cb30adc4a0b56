"""Benchmark: ``diagnose`` on 60 s of 7-joint data at 1 kHz with every candidate (target <= 60 s): all
eleven plain kinds, the composed library (effect x modulating signal), the friction-law stage, the
stability stage (OLS and WLS weights, time-blocked folds) and the unexplained-structure stage.

Simulated KUKA LWR4 recording (generated model ``lwr4``, random physical parameters with LWR-like
friction, Fourier excitation) with three effects the model lacks (Stribeck friction on joint 2, a
10 ms torque lag on joint 1, a position ripple on joint 6: four rounds of the loop), noise on q and
torque; the last 30 % held out for validation. Prints the wall time and the effects found.

    PYTHONPATH=. python bench/bench_diagnose.py [--seconds 60] [--rate 1000]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import symoro_gen
from symoro_gen.description import load_robot
from symoro_gen.diagnostics import KINDS, diagnose, inject_effect
from symoro_gen.preprocessing.trajectory import Trajectory
from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, true_torques

TARGET_S = 60.0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--rate", type=float, default=1000.0)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args(argv)
    rng = np.random.default_rng(a.seed)
    t0 = time.perf_counter()
    model = symoro_gen.load_model("lwr4")
    robot = load_robot("lwr4")
    t, q, dq, ddq = fourier_trajectory(7, a.seconds, 1.0 / a.rate, rng, base_frequency_hz=0.1)
    chi = np.asarray(random_physical_parameters(robot, rng, fs_range=(0.1, 0.5), fv_range=(0.1, 1.0)))
    tau = true_torques(model, q, dq, ddq, chi)
    qm, taum = inject_effect("stribeck", t, q, dq, ddq, tau, joint=1, Fst=0.5, vs=0.05)
    _, taum = inject_effect("time_delay", t, q, dq, ddq, taum, joint=0, delay=0.01)
    _, taum = inject_effect("position_ripple", t, q, dq, ddq, taum, joint=5, amplitude=0.2, k=8)
    qm = qm + 1e-5 * rng.standard_normal(qm.shape)
    taum = taum + 0.05 * rng.standard_normal(taum.shape)
    tr = Trajectory(t=t, q=qm, tau=taum, source="simulated lwr4")
    t1 = time.perf_counter()
    c1 = time.process_time()
    rep = diagnose(model, tr, rng=np.random.default_rng(0))   # default: every kind, friction laws, composed
    t2 = time.perf_counter()
    c2 = time.process_time()
    n_tried = len(rep.tried)
    print(f"data: {tr.n_samples} samples x {tr.n_joints} joints at {a.rate:g} Hz ({a.seconds:g} s); "
          f"simulation {t1 - t0:.1f} s")
    print(f"diagnose (all {len(KINDS)} kinds, {n_tried} candidate evaluations, {len(rep.effects)} effect(s) "
          f"added: {', '.join(e.label for e in rep.effects) or 'none'}): {t2 - t1:.1f} s "
          f"(target <= {TARGET_S:g} s) {'OK' if t2 - t1 <= TARGET_S else 'SLOW'}; CPU time of this process "
          f"{c2 - c1:.1f} s (wall time counts other processes sharing the cores)")
    print("validation rel. err. before: " + " ".join(f"{x:.4f}" for x in rep.before_validation_rel_err))
    print("validation rel. err. after:  " + " ".join(f"{x:.4f}" for x in rep.after_validation_rel_err))
    print("friction laws: " + ("; ".join(rep.settings["friction_law_choices"]) or "declared laws kept"))
    print("unexplained: " + (", ".join(f"joint {u['joint']} {u['share']:.2f}" for u in rep.to_dict()["unexplained"])
                             or "none"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
