"""``fleet`` gives the warnings ``identify`` and ``diagnose`` give on a recording (a joint held at its encoder
noise, a torque clipped at its limit), per log, naming the robot, the day, the log and the joint, with what to
do (fleet has neither ``--drop-unexcited`` nor ``--drop-saturated``), in its text, its warnings and its JSON;
the untouched logs give none."""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from symoro_gen.fleet import read_log, simulate_fleet, write_parquet
from symoro_gen.preprocessing.readers import DataWarning


def test_fleet_warns_per_log_of_a_stuck_joint_and_a_saturated_torque(tmp_path, cli):
    simulate_fleet(tmp_path, "scara", n_robots=3, n_days=2, duration=2.0, drifts=(), seed=4)
    rng = np.random.default_rng(0)
    stuck, sat = tmp_path / "r01" / "d01.parquet", tmp_path / "r02" / "d00.parquet"
    tr = read_log(str(stuck), 4)
    q = np.array(tr.q)
    q[:, 0] = 0.3 + rng.normal(0.0, 1e-5, len(q))          # joint 1 held still: its encoder noise only
    write_parquet(stuck, dataclasses.replace(tr, q=q))
    tr = read_log(str(sat), 4)
    tau = np.array(tr.tau)
    lim = np.quantile(np.abs(tau[:, 1]), 0.7)
    tau[:, 1] = np.clip(tau[:, 1], -lim, lim)                # tau2 clipped: 30 % of the samples at the limit
    write_parquet(sat, dataclasses.replace(tr, tau=tau))
    out = tmp_path / "fleet.json"
    with pytest.warns(DataWarning) as rec:  # the command line prints each as a `symoro-gen: warning:` line
        r = cli("fleet", "scara", tmp_path, "--by", "{robot}/{day}.parquet", "--scheduler", "threads:2", "--json",
                out)
    doc = json.loads(out.read_text())
    assert len(doc["warnings"]) == 2, doc["warnings"]
    w_stuck = next(w for w in doc["warnings"] if "does not move" in w)
    w_sat = next(w for w in doc["warnings"] if "clipped" in w)
    assert w_stuck.startswith(f"robot r01, day d01: {stuck}: joint 1 (position RMS ")
    assert "--drop-unexcited" in w_stuck and "joint 2" not in w_stuck
    assert w_sat.startswith(f"robot r02, day d00: {sat}: tau2 at its limit ")
    share = float(w_sat.split("at its limit ")[1].split(" %")[0])
    assert 25.0 <= share <= 35.0 and "--drop-saturated" in w_sat and "tau1" not in w_sat
    assert sorted(str(w.message) for w in rec if w.category is DataWarning) == sorted(doc["warnings"])
    assert f"  warning: {w_stuck}" in r.out.splitlines() and f"  warning: {w_sat}" in r.out.splitlines()
