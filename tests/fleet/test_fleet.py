"""Fleet identification: exactness of the distributed TSQR against the single-process
accumulator, a lost worker, a damaged log, drift detection on simulated fleets, the JSON contract."""
from __future__ import annotations

import functools
import itertools
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2 as st_chi2

from symoro_gen import load_model
from symoro_gen.errors import DataFileError
from symoro_gen.fleet import (
    Drift,
    FleetError,
    FleetOptions,
    compile_pattern,
    discover,
    identify_fleet,
    open_client,
    read_log,
    simulate_fleet,
    write_parquet,
)
from symoro_gen.fleet.fused import fold_trajectories, fold_trajectory
from symoro_gen.fleet.stats import (
    DISPERSION_SCREEN_P,
    HAMPEL_C,
    adjust,
    dersimonian_laird,
    dispersion_outliers,
    hampel_outliers,
    level_z,
    line_fit,
    pooled_dispersion,
    trend_test,
)
from symoro_gen.identification import fit_wls
from symoro_gen.observations import AssemblyOptions
from symoro_gen.preprocessing.readers import load_trajectory
from symoro_gen.preprocessing.trajectory import Trajectory
from symoro_gen.simulate import write_recording_csv

from .killer import kill_once

BY = "{robot}/{day}.*"


@pytest.fixture(scope="module")
def small_fleet(tmp_path_factory):
    """3 robots x 3 days of 4 s, scara; one log rewritten as CSV (mixed formats)."""
    root = tmp_path_factory.mktemp("fleet")
    truth = simulate_fleet(root, "scara", n_robots=3, n_days=3, duration=4.0, drifts=(), seed=3)
    pq = root / "r02" / "d01.parquet"
    write_recording_csv(root / "r02" / "d01.csv", read_log(str(pq), 4))
    pq.unlink()
    return root, truth


@pytest.fixture(scope="module")
def threads_client():
    with open_client("threads:2") as c:
        yield c


def _read(f):
    return load_trajectory(f.path, n_joints=4) if f.path.endswith(".csv") else read_log(f.path, 4)


def _reference(model, files, opts):
    """The single-process accumulator on the same files (no Dask, no merge): IDIM-WLS of each robot-day."""
    return {(f.robot, f.day): fit_wls(fold_trajectory(model, _read(f), opts)) for f in files}


def _close(a, b, rtol=1e-10):
    """Relative to the vector's norm (an element near zero makes an elementwise ratio meaningless; the
    summation order of the distributed reduction moves the last bits, ~4e-12 absolute here)."""
    a, b = np.asarray(a), np.asarray(b)
    return np.linalg.norm(a - b) <= rtol * max(np.linalg.norm(b), 1e-300)


@pytest.mark.parametrize("chunk_samples", [None, 1300])
def test_distributed_equals_single_process(small_fleet, threads_client, chunk_samples):
    """Per robot-day estimates and the fleet factor equal those of the plain single-process accumulator
    (whatever the block size, with 2 threads here and 2 worker processes in the lost-worker test)."""
    root, _ = small_fleet
    model = load_model("scara")
    opts = AssemblyOptions(keep_signals=False, chunk_samples=chunk_samples)
    files = discover([root], BY)
    assert {f.path[-4:] for f in files} == {".csv", "quet"}
    ref = _reference(model, files, opts)   # same blocks: the filters' block borders are part of the method
    res = identify_fleet("scara", [root], BY, client=threads_client, assembly=opts)
    assert not res.skipped
    for (r, d), fit in ref.items():
        e = res.days[r][d]
        assert e.names == tuple(fit.names)
        assert _close(e.values, fit.values), (r, d, np.abs(e.values - fit.values).max())
        # std carries sigma^2 = (|y|^2 - |Q'y|^2) / (r - p): a difference of two close sums, whose last
        # bits depend on the summation order (C vs NumPy kernel, block tree): 1e-8 relative
        assert _close(e.std, fit.std, rtol=1e-8), (r, d)
    # the fleet factor is the factor of every row: same Gram matrix as one accumulator fed every log
    one = fold_trajectories(model, [_read(f) for f in files], opts)
    acc = res.partials["fleet"].acc
    for j in range(4):
        G, G1 = acc.R[j].T @ acc.R[j], one.R[j].T @ one.R[j]
        assert np.max(np.abs(G - G1)) <= 1e-10 * np.max(np.abs(G1))
    assert acc.rows == one.rows


def test_segments_are_tasks_of_bounded_memory_and_exact(small_fleet, threads_client, tmp_path):
    """Logs cut into segments (read row group by row group) give the single-process accumulator over the
    same segments taken as experiments, sliced from the whole log."""
    root0, _ = small_fleet
    root = tmp_path / "f"
    shutil.copytree(root0, root)
    whole = read_log(str(root / "r00" / "d00.parquet"), 4)
    write_parquet(root / "r00" / "d00.parquet", whole, row_group_size=700)     # several row groups
    res = identify_fleet("scara", [root], BY, FleetOptions(segment_samples=1500), client=threads_client)
    assert res.settings["tasks"] == 3 * 8 + 1 and not res.skipped            # 8 Parquet logs of 4001 samples, 1 CSV
    model = load_model("scara")
    opts = AssemblyOptions(keep_signals=False)
    bounds = [0, 1334, 2667, 4001]
    parts = [Trajectory(t=whole.t[a:b], q=whole.q[a:b], tau=whole.tau[a:b], source=f"[{a}:{b}]")
             for a, b in itertools.pairwise(bounds)]
    ref = fit_wls(fold_trajectories(model, parts, opts))
    assert _close(res.days["r00"]["d00"].values, ref.values)
    assert res.days["r00"]["d00"].samples == 4001


@pytest.mark.slow
def test_lost_worker_is_retried_and_result_unchanged(small_fleet, threads_client, tmp_path):
    root, _ = small_fleet
    base = identify_fleet("scara", [root], BY, client=threads_client)
    marker = tmp_path / "killed"
    res = identify_fleet("scara", [root], BY, FleetOptions(scheduler="local:2", retries=3),
                         kernel=functools.partial(kill_once, marker=str(marker)))
    assert marker.exists(), "no worker was killed"
    assert res.settings["workers"] >= 1 and not res.skipped
    for r in base.days:
        for d in base.days[r]:
            assert _close(res.days[r][d].values, base.days[r][d].values)
    assert _close(res.fleet.values, base.fleet.values)


def test_damaged_log_is_skipped_and_named(small_fleet, threads_client, tmp_path):
    root0, _ = small_fleet
    root = tmp_path / "f"
    shutil.copytree(root0, root)
    bad = root / "r01" / "d02.parquet"
    bad.write_bytes(b"PAR1 this is not a parquet file" * 10)
    res = identify_fleet("scara", [root], BY, client=threads_client)
    assert [s["file"] for s in res.skipped] == [str(bad)]
    assert str(bad) in res.skipped[0]["error"]
    assert "d02" not in res.days["r01"] and "d01" in res.days["r01"]
    clean = identify_fleet("scara", [root0], BY, client=threads_client)
    for r in ("r00", "r02"):          # the other robots are not poisoned: same numbers as without the bad file
        for d in clean.days[r]:
            assert _close(res.days[r][d].values, clean.days[r][d].values)
    assert _close(res.days["r01"]["d00"].values, clean.days["r01"]["d00"].values)
    assert str(bad) in res.summary()


def test_nothing_usable_fails_with_the_files(tmp_path, threads_client):
    (tmp_path / "a").mkdir()
    f = tmp_path / "a" / "d1.parquet"
    f.write_bytes(b"garbage")
    with pytest.raises(FleetError, match=r"d1\.parquet"):
        identify_fleet("scara", [str(f)], "{robot}/{day}.parquet", client=threads_client)


def _joint_of(name: str) -> int:
    return int(re.search(r"(\d+)R?$", name).group(1))


@pytest.mark.parametrize("seed", [11, 12, 13])
def test_drifting_robots_flagged_and_no_other(tmp_path, threads_client, seed):
    drifts = (Drift("r01", "FV4", 0.06), Drift("r03", "gain", -0.04, joint=1))
    truth = simulate_fleet(tmp_path, "scara", n_robots=6, n_days=4, duration=8.0, drifts=drifts, seed=seed,
                           friction_scatter=0.04)
    res = identify_fleet("scara", [tmp_path], "{robot}/{day}.parquet", client=threads_client)
    flagged = {}
    for f in res.flagged:
        flagged.setdefault(f["robot"], []).append(f["parameter"])
    assert set(flagged) == truth.drifting, res.summary()
    assert "FV4" in flagged["r01"]
    # a torque gain of joint 1 scales the rows of joint 1: its own parameters (friction, offset) move with it
    # and the parameters shared with other joints' rows follow a little; the strongest flag is joint 1's
    top = next(f for f in res.flagged if f["robot"] == "r03")
    assert _joint_of(top["parameter"]) == 1, flagged["r03"]
    assert {"FV1", "FS1"} <= set(flagged["r03"])


def test_unit_scatter_alone_is_never_flagged(tmp_path, threads_client):
    simulate_fleet(tmp_path, "scara", n_robots=8, n_days=3, duration=6.0, drifts=(), seed=5, friction_scatter=0.05)
    res = identify_fleet("scara", [tmp_path], "{robot}/{day}.parquet", client=threads_client)
    assert res.flagged == []
    # the scatter is there and seen: the between-robot spread of the friction parameters is not zero
    k = res.names.index("FV2")
    assert res.level["tau_all"][k] > 0


def test_json_contract_and_report_from_the_cli(small_fleet, cli, tmp_path):
    root, _ = small_fleet
    out, rep = tmp_path / "fleet.json", tmp_path / "fleet.html"
    r = cli("fleet", "scara", str(root / "*" / "*"), "--by", BY, "--scheduler", "threads:2", "--json", out,
            "--report", rep)
    assert "no robot drifts" in r.out
    doc = json.loads(out.read_text())
    assert set(doc) >= {"robots", "fleet", "flagged"}
    assert doc["flagged"] == []
    assert sorted(doc["robots"]) == ["r00", "r01", "r02"]
    for rob in doc["robots"].values():
        assert sorted(rob["days"]) == ["d00", "d01", "d02"]
        for day in rob["days"].values():
            assert len(day["names"]) == len(day["values"]) == len(day["std"]) == 22
            assert all(s > 0 for s in day["std"])
    assert len(doc["fleet"]["names"]) == len(doc["fleet"]["values"]) == len(doc["fleet"]["std"]) == 22
    assert rep.read_text().startswith("<!DOCTYPE html>")


def test_flagged_json_entries_and_plots(tmp_path, threads_client):
    pytest.importorskip("matplotlib", reason="plots extra")
    from symoro_gen.fleet.report import write_fleet_report

    simulate_fleet(tmp_path / "logs", "scara", n_robots=4, n_days=3, duration=6.0,
                   drifts=(Drift("r02", "FS2", 0.2),), seed=2)
    res = identify_fleet("scara", [tmp_path / "logs"], "{robot}/{day}.parquet", client=threads_client)
    doc = json.loads(json.dumps(res.to_dict()))
    assert doc["flagged"] and all(f["robot"] == "r02" for f in doc["flagged"])
    f = doc["flagged"][0]
    assert set(f) >= {"robot", "parameter", "z", "days"} and isinstance(f["z"], float)
    assert set(f["days"]) <= {"d00", "d01", "d02"} and f["days"]
    html = write_fleet_report(tmp_path / "r.html", res).read_text()
    assert html.count("<img") == len(res.flagged)


def test_pattern_and_discovery(tmp_path):
    rx = compile_pattern("{robot}/{day}.parquet")
    assert rx.search("/data/plant/arm07/2026-03-01.parquet").groupdict() == {"robot": "arm07", "day": "2026-03-01"}
    assert rx.search("/data/arm07/2026-03-01.csv") is None
    with pytest.raises(FleetError, match="robot"):
        compile_pattern("{day}.csv")
    for r, d in (("b", "2"), ("a", "10"), ("a", "9")):
        (tmp_path / r).mkdir(exist_ok=True)
        (tmp_path / r / f"{d}.csv").write_text("x")
    got = [(f.robot, f.day) for f in discover([tmp_path / "*" / "*.csv"], "{robot}/{day}.csv")]
    assert got == [("a", "10"), ("a", "9"), ("b", "2")]       # days sort as strings
    with pytest.raises(DataFileError, match="no file matches"):
        discover([tmp_path / "*.nothing"], "{robot}/{day}.csv")
    with pytest.raises(DataFileError, match="does not end like"):
        discover([tmp_path / "a" / "9.csv"], "{robot}/{day}.parquet")


def test_statistics_against_direct_definitions():
    rng = np.random.default_rng(0)
    theta, var = rng.normal(1.0, 0.2, 7), rng.uniform(0.01, 0.05, 7)
    m, _vm, t2 = dersimonian_laird(theta, var)
    w = 1 / var
    mfe = w @ theta / w.sum()
    Q = w @ (theta - mfe) ** 2
    t2_ref = max(0.0, (Q - 6) / (w.sum() - (w ** 2).sum() / w.sum()))
    assert np.isclose(t2, t2_ref) and np.isclose(m, (theta / (var + t2)).sum() / (1 / (var + t2)).sum())
    # Holm and BH against their textbook step procedures
    p = rng.uniform(0, 0.02, 12)
    rej, _ = adjust(p, 0.05, "holm")
    srt = np.sort(p)
    k = next((i for i in range(12) if srt[i] > 0.05 / (12 - i)), 12)
    assert rej.sum() == k
    rej, _ = adjust(p, 0.05, "bh")
    kk = max([i + 1 for i in range(12) if srt[i] <= 0.05 * (i + 1) / 12], default=0)
    assert rej.sum() == kk
    # the trend slope is the weighted least-squares slope
    x = np.arange(6.0)
    y = 2.0 + 0.3 * x + rng.normal(0, 0.01, 6)
    s = np.full(6, 0.01)
    slope, _se, z, pv = trend_test(x, y, s)
    assert np.isclose(slope, np.polyfit(x, y, 1)[0]) and z > 10 and pv < 1e-6


def test_trend_reference_distributions():
    """The trend's standard error and p-value against ordinary least squares (scipy's linregress: the
    scale estimated from the residuals, Student's t with D - 2 dof) when the days scatter more than their
    sigmas; the pooled fleet dispersion with its dof; the plain normal test when the sigmas hold."""
    from scipy import stats as st

    rng = np.random.default_rng(1)
    x = np.arange(5.0)
    y = 1.0 + 0.02 * x + rng.normal(0, 0.01, 5)
    s = np.full(5, 0.001)                          # sigmas 10x too small: the own Birge ratio sets the scale
    slope, se, z, p = trend_test(x, y, s)
    ref = st.linregress(x, y)
    assert np.isclose(slope, ref.slope) and np.isclose(se, ref.stderr) and np.isclose(p, ref.pvalue)
    # a fleet dispersion larger than the robot's own: it sets the scale, with its degrees of freedom
    own = (ref.stderr / (0.001 / np.sqrt(10.0))) ** 2
    slope, se, z, p = trend_test(x, y, s, dispersion=4 * own, dof=12)
    assert np.isclose(se, 2 * ref.stderr) and np.isclose(p, 2 * st.t.sf(abs(z), 12))
    # the robot's own ratio above the fleet's: it sets the scale (a guard), the pooled dof the reference
    slope, se, z, p = trend_test(x, y, s, dispersion=own / 4, dof=12)
    assert np.isclose(se, ref.stderr) and np.isclose(p, 2 * st.t.sf(abs(z), 12))
    # sigmas that hold (scatter below them): the slope's own standard error, normal reference
    s = np.full(5, 0.05)
    slope, se, z, p = trend_test(x, y, s, dispersion=0.5, dof=12)
    assert np.isclose(se, 0.05 / np.sqrt(10.0)) and np.isclose(p, 2 * st.norm.sf(abs(z)))
    # pooling: sum of chi2 over sum of dof, robots without a line (NaN, dof 0) left out
    assert pooled_dispersion(np.array([3.0, np.nan, 1.0]), np.array([3, 0, 1])) == (1.0, 4)
    assert np.isnan(pooled_dispersion(np.array([np.nan]), np.array([0]))[0])


@pytest.mark.parametrize("seed", [2, 3])
def test_a_far_robot_no_longer_masks_a_milder_one(tmp_path, threads_client, seed):
    """12 robots; r01's FV4 is 100 % off the fleet (small sigma: a unit that was never like the others), r02's
    40 %. Plain leave-one-out DerSimonian-Laird lets r01 into r02's reference: the between-robot spread
    becomes ~r01's distance / sqrt(11), r02's z falls below 1 (masked) and r01's own z is deflated by r02.
    With the Hampel screen (robots beyond 5 robust sigmas out of the others' references) both are flagged
    on FV4, the z's grow several-fold, and no clean robot is flagged."""
    drifts = (Drift("r01", "FV4", 0.0, offset=1.0), Drift("r02", "FV4", 0.0, offset=0.4))
    simulate_fleet(tmp_path, "scara", n_robots=12, n_days=3, duration=5.0, drifts=drifts, seed=seed)
    res = identify_fleet("scara", [tmp_path], "{robot}/{day}.parquet", client=threads_client)
    k = res.names.index("FV4")
    rn = list(res.robots)
    theta = np.array([res.robots[r].values for r in rn])
    std = np.array([res.robots[r].std for r in rn])
    before = level_z(theta, std, robust=False)[0][:, k]
    after = res.level["z"][:, k]
    i1, i2 = rn.index("r01"), rn.index("r02")
    assert abs(before[i2]) < 2.0 and after[i2] > 3 * abs(before[i2]) + 5, (before, after)
    assert after[i1] > 2 * before[i1], (before, after)
    assert {(f["robot"], f["parameter"]) for f in res.flagged if f["parameter"] == "FV4"} == {("r01", "FV4"),
                                                                                             ("r02", "FV4")}
    assert {f["robot"] for f in res.flagged} == {"r01", "r02"}, res.summary()
    # the fleet's reported spread is the clean robots' (r01, r02 screened out): a few % of FV4, not ~30 %
    assert res.level["tau_all"][k] < 0.1 * abs(res.fleet.values[k])


def test_robust_reference_statistics():
    """The Hampel screen against its definition; on fleets without outliers it changes nothing (same numbers)
    and flags no more clean robots than the plain reference (100 simulated fleets of 10 robots x 20
    parameters, Holm at 1 %); with a robot 40 between-robot sigmas away, a second one 10 sigmas away is
    found (never before: masked) and clean robots are still not flagged more often."""
    rng = np.random.default_rng(0)
    theta, var = rng.normal(0.0, 1.0, 9), rng.uniform(0.01, 0.04, 9)
    theta[4] = 9.0
    med = np.median(theta)
    s = 1.4826 * np.median(np.abs(theta - med))
    assert np.array_equal(hampel_outliers(theta, var), np.abs(theta - med) > HAMPEL_C * np.sqrt(s * s + var))
    assert hampel_outliers(theta, var).tolist() == [i == 4 for i in range(9)]
    assert not hampel_outliers(theta[:4], var[:4]).any()        # too few robots: no screen
    R, P, tau = 10, 20, 0.1
    counts = {"clean": [0, 0], "masked": [0, 0], "masked_clean": [0, 0]}
    for seed in range(100):
        g = np.random.default_rng(seed)
        sd = g.uniform(0.02, 0.1, (R, P))
        th = 1.0 + tau * g.standard_normal((R, P)) + sd * g.standard_normal((R, P))
        other = g.uniform(0, 1, (R, P))                          # the trend tests' p-values: uniform when clean
        for j, robust in enumerate((False, True)):
            z, p, *_ = level_z(th, sd, robust=robust)
            counts["clean"][j] += adjust(np.stack([p, other]), 0.01)[0][0].any()
        if not hampel_outliers(th[:, 0], sd[:, 0] ** 2).any():
            z0, z1 = level_z(th, sd, robust=False)[0][:, 0], level_z(th, sd)[0][:, 0]
            assert np.array_equal(z0, z1)
        th[0, 3] += 40 * tau
        th[1, 3] += 10 * tau
        for j, robust in enumerate((False, True)):
            z, p, *_ = level_z(th, sd, robust=robust)
            rej = adjust(np.stack([p, other]), 0.01)[0][0]
            counts["masked"][j] += rej[1, 3]
            rej[:2, 3] = False
            counts["masked_clean"][j] += rej.any()
    assert counts["masked"][0] == 0 and counts["masked"][1] >= 25, counts
    assert counts["clean"][1] <= counts["clean"][0] + 1 and counts["clean"][1] <= 3, counts
    assert counts["masked_clean"][1] <= counts["masked_clean"][0] + 1 and counts["masked_clean"][1] <= 3, counts


def _trend_flags(y, sd, robust):
    """Holm-adjusted trend flags (R, P) of day series y (R, D, P) with daily sigmas sd, as the engine
    computes them (pooled dispersion per parameter), beside uniform level p-values."""
    R, D, P = y.shape
    x = np.arange(D, dtype=float)
    fits = [[line_fit(x, y[r, :, k], sd[r, :, k]) for k in range(P)] for r in range(R)]
    chi2 = np.array([[f[2] for f in row] for row in fits])
    nu = np.array([[f[3] for f in row] for row in fits])
    pt = np.empty((R, P))
    for k in range(P):
        phi, dof = pooled_dispersion(chi2[:, k], nu[:, k], robust=robust)
        for r in range(R):
            pt[r, k] = trend_test(x, y[r, :, k], sd[r, :, k], dispersion=phi, dof=dof)[3]
    other = np.random.default_rng(R * D * P).uniform(0, 1, (R, P))
    return adjust(np.stack([other, pt]), 0.01)[0][1]


@pytest.mark.slow
def test_a_wildly_scattering_robot_no_longer_masks_a_drift():
    """10 robots x 6 days x 20 parameters whose days scatter 1.5x their sigmas. Robot 0's days on parameter 3
    scatter 30x (a faulty log series), robot 1 drifts there by 3 sigmas a day. Pooled over all robots, robot
    0's scatter sets the slope error of every robot (the pooled ratio ~ 90 instead of 2.25) and robot 1's
    drift is never found; with robot 0 screened out of the pool (``dispersion_outliers``) it is found in
    >= 80 of 100 fleets, robot 0 itself (no trend, its own large ratio) is not flagged, and clean fleets are
    flagged no more often than with the plain pool."""
    R, D, P = 10, 6, 20
    counts = {"found": [0, 0], "wild_flagged": [0, 0], "clean": [0, 0]}
    for seed in range(100):
        g = np.random.default_rng(seed)
        sd = np.full((R, D, P), 0.01)
        y = 1.0 + 1.5 * sd * g.standard_normal((R, D, P))
        for j, robust in enumerate((False, True)):
            counts["clean"][j] += _trend_flags(y, sd, robust).any()
        fits = [line_fit(np.arange(float(D)), y[r, :, 0], sd[r, :, 0]) for r in range(R)]
        scr = dispersion_outliers(np.array([f[2] for f in fits]), np.array([f[3] for f in fits]))
        assert scr.sum() <= 1                 # a robot sharing the dispersion: screened with chance 1e-4 each
        y[0, :, 3] = 1.0 + 30 * sd[0, :, 3] * g.standard_normal(D)
        y[1, :, 3] += 3 * 0.01 * np.arange(D)
        for j, robust in enumerate((False, True)):
            rej = _trend_flags(y, sd, robust)
            counts["found"][j] += rej[1, 3]
            counts["wild_flagged"][j] += rej[0, 3]
    assert counts["found"][0] <= 5 and counts["found"][1] >= 80, counts
    assert counts["wild_flagged"][1] <= 2, counts
    assert counts["clean"][1] <= counts["clean"][0] + 1 and counts["clean"][1] <= 3, counts


def test_dispersion_screen_definition():
    g = np.random.default_rng(3)
    nu = np.array([4, 4, 3, 4, 2, 4, 4, 0])
    chi2 = 2.0 * g.chisquare(np.maximum(nu, 1)).astype(float)
    chi2[7] = np.nan                          # no line
    chi2[2] = 200.0
    ok = nu > 0
    phi0 = np.median(chi2[ok] / st_chi2.median(nu[ok]))
    want = np.zeros(8, bool)
    want[ok] = chi2[ok] > phi0 * st_chi2.isf(DISPERSION_SCREEN_P, nu[ok])
    assert np.array_equal(dispersion_outliers(chi2, nu), want) and want.tolist() == [i == 2 for i in range(8)]
    assert not dispersion_outliers(chi2[:4], nu[:4]).any()            # 4 robots: no screen
    # pooled without the screened robot, and the plain pool on request
    phi, dof = pooled_dispersion(chi2, nu)
    keep = ok & ~want
    assert np.isclose(phi, chi2[keep].sum() / nu[keep].sum()) and dof == nu[keep].sum()
    assert np.isclose(pooled_dispersion(chi2, nu, robust=False)[0], np.nansum(chi2[ok]) / nu[ok].sum())


@pytest.mark.parametrize("seed", [12, 16, 27])
def test_few_robots_short_logs_no_false_flag(tmp_path, threads_client, seed):
    """4 robots x 5 days x 5 s: one robot's daily sigmas say less than its days scatter, and 3 others
    estimate the fleet's spread poorly. Seed 12 flagged a clean robot's ZZ4/MX4 trend (z = 4.4 against a
    normal reference with its own 3-dof Birge ratio); with the pooled dispersion and the t reference no
    clean robot is flagged and the drifting one still is."""
    simulate_fleet(tmp_path, "scara", n_robots=4, n_days=5, duration=5.0, drifts=(Drift("r01", "FV4", 0.06),),
                   seed=seed)
    res = identify_fleet("scara", [tmp_path], "{robot}/{day}.parquet", client=threads_client)
    assert {f["robot"] for f in res.flagged} == {"r01"}, res.summary()
    assert "FV4" in [f["parameter"] for f in res.flagged]
    assert np.all(res.trend["dof"] == 4 * 3)


def test_cli_errors_name_the_file_and_the_pattern(cli, tmp_path):
    r = cli("fleet", "scara", tmp_path / "missing.parquet", "--by", "{robot}/{day}.parquet", rc=2)
    assert "missing.parquet: no such file" in r.err_lines[0]
    r = cli("fleet", "scara", tmp_path, "--by", "{day}.parquet", rc=2)
    assert "must contain {robot} and {day}" in r.err_lines[0]
    r = cli("fleet", "scara", tmp_path, "--by", "{robot}/{day}.parquet", "--alpha", "2", rc=2)
    assert "alpha" in r.err_lines[0]


_FAULTS = """
import resource, sys
import numpy as np
from symoro_gen.fleet.worker import tune_malloc
if sys.argv[1] == "tuned":
    assert tune_malloc()
a = np.ones(1 << 19)                    # 4 MB, as a log's column or a filter block
f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(100):
    b = a * 2.0                         # allocated, written and freed every time
    del b
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0)
"""


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_tune_malloc_stops_page_faults_under_dasks_trim_setting():
    """Under the environment a Dask nanny gives its workers (MALLOC_TRIM_THRESHOLD_=65536), every 4 MB array
    is fresh mmap pages (faulted in on every use); tune_malloc keeps them in the heap."""
    env = dict(os.environ, MALLOC_TRIM_THRESHOLD_="65536", OPENBLAS_NUM_THREADS="1")
    faults = {}
    for mode in ("dask", "tuned"):
        out = subprocess.run([sys.executable, "-c", _FAULTS, mode], env=env, capture_output=True, text=True,
                             check=True)
        faults[mode] = int(out.stdout.split()[-1])
    # measured 51k faults (the array's pages faulted in again on every iteration) against 513 (once)
    assert faults["dask"] > 100 * 200, faults
    assert faults["tuned"] * 20 < faults["dask"], faults


def test_worker_setup_once_per_worker_process(small_fleet, threads_client):
    """A worker process gets the malloc settings and the model before its first task; the result is that of
    the in-process run."""
    root, _ = small_fleet
    base = identify_fleet("scara", [root], BY, client=threads_client)
    with open_client("local:1") as client:
        res = identify_fleet("scara", [root], BY, client=client)
        state = client.run(lambda dask_worker: [(p.malloc_tuned, p.preloaded) for n, p in
                                                dask_worker.plugins.items() if n.startswith("symoro-fleet-setup")])
    assert list(state.values()) == [[(True, True)]], state
    assert not res.skipped and _close(res.fleet.values, base.fleet.values)
    # in the client's own process (threads:N) the allocator is left alone, the model still preloaded
    worker = next(iter(threads_client.cluster.workers.values()))
    own = [(p.malloc_tuned, p.preloaded) for n, p in worker.plugins.items() if n.startswith("symoro-fleet-setup")]
    assert own == [(False, True)], own


def test_worker_model_cache_follows_a_regenerated_package(tmp_path):
    """The per-process model cache is keyed by the package's content: a long-lived worker whose
    generated model is rewritten in place uses the new one (and its own column map), never a stale one."""
    from symoro_gen.fleet.kernel import resolve_model
    from symoro_gen.loader import generated_dir
    from symoro_gen.observations.fused import model_column_map

    pkg = tmp_path / "scara"
    shutil.copytree(generated_dir() / "scara", pkg, ignore=shutil.ignore_patterns("__pycache__"))
    m1 = resolve_model(str(pkg))
    assert resolve_model(str(pkg)) is m1                      # cached while unchanged
    init = pkg / "__init__.py"
    init.write_text(init.read_text() + "\n# regenerated\n")
    m2 = resolve_model(str(pkg))
    assert m2 is not m1 and model_column_map(m2) is not model_column_map(m1)
    assert resolve_model(str(pkg)) is m2


def test_worker_path_does_not_import_the_engine():
    """What a worker unpickles (the per-log task, the merge, the setup plugin) imports neither the engine nor
    what only the client needs (the statistics, the closed-loop diagnosis): the package's names load on
    first use; and they are still all there."""
    code = ("import sys, symoro_gen.fleet.kernel, symoro_gen.fleet.worker\n"
            "bad = [m for m in ('symoro_gen.fleet.engine', 'symoro_gen.fleet.stats', 'symoro_gen.diagnostics',"
            " 'symoro_gen.fleet.simulate') if m in sys.modules]\n"
            "import symoro_gen.fleet as f\n"
            "missing = [n for n in f.__all__ if getattr(f, n, None) is None]\n"
            "print(bad, missing)\n")
    root = str(Path(__file__).resolve().parents[2])
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")])))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True).stdout
    assert out.strip() == "[] []", out
    import symoro_gen.fleet as f
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        f.nothing  # noqa: B018
