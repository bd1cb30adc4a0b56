"""The friction-law stage's replacements compete with the loop's candidates in the same round.

A torque delay leaves its largest residual at the velocity reversals, where a Stribeck-shaped Coulomb law
can absorb part of it. Simulated by the truth bench's independent simulator (``bench/truthsim.py``: Pinocchio
RNEA, the delay written as ``tau(t - d)``), a 10 ms delay on every joint of the LWR4 must be named first - a
friction law may follow only if it still passes its tests once the delay is in the model.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pytest

import symoro_gen
from symoro_gen.description import load_robot
from symoro_gen.diagnostics import DiagnoseSettings, diagnose

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))
try:
    import bench_loop_truth as blt
    import truthsim as ts
finally:
    sys.path.remove(str(ROOT / "bench"))


@pytest.mark.slow
def test_an_all_joint_delay_is_named_before_any_friction_law():
    robot = load_robot("lwr4")
    model = symoro_gen.load_model("lwr4")
    chi, _ = ts.nominal_parameters(robot)
    rigid = ts.Rigid(robot, chi)
    (case,) = [c for c in blt.cases() if c.number == 1]   # tau_meas(t) = tau(t - 10 ms) on every joint
    a = argparse.Namespace(seconds=30.0, rate=500.0, sigma_tau=0.05, seed=0)
    rng = np.random.default_rng(1)
    truth = blt.lwr4_truth(robot, chi, a.sigma_tau)
    case.set_up(truth)
    ident, _ = ts.record(robot, rigid, ts.sum_of_sines(robot, rng), truth, a.seconds, a.rate, rng, "ident",
                         growth_time=a.seconds)
    valid, _ = ts.record(robot, rigid, ts.sum_of_sines(robot, rng), truth, 0.5 * a.seconds, a.rate, rng, "valid",
                         growth_time=a.seconds)
    rep = diagnose(model, [ident], DiagnoseSettings(), validation=[valid], rng=np.random.default_rng(1))
    kinds = [(e.kind, e.joint) for e in rep.effects]
    assert kinds and kinds[0] == ("time_delay", None), kinds
    first = rep.effects[0]
    assert first.values[0] == pytest.approx(0.010, rel=0.15)
    assert first.verdict == "cause", first.verdict_reason
    # a friction law named after it won a later round (it still passed its tests with the delay in the model)
    assert all(e.round > first.round for e in rep.effects if e.kind == "friction_law"), kinds
