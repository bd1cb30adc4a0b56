"""A fleet's per-day estimates are ``identify``'s on the same file: at every sampling rate, at the edges of the
filters' rule, and when ``generated/<robot>/`` was written from another robot file than ``robots/<robot>.toml``
(the fleet then used that package while ``identify`` used the robot file). Both recover the simulated truth;
a drifting unit is flagged, clean fleets are not.

The reference is the ``identify`` command itself (its JSON), never the fleet's own in-process path.
"""
from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from symoro_gen import load_model
from symoro_gen.fleet import Drift, identify_fleet, open_client, simulate_fleet
from symoro_gen.loader import model_for, robots_dir

BY = "{robot}/{day}.parquet"


@pytest.fixture(scope="module")
def threads_client():
    with open_client("threads:2") as c:
        yield c


def _identify(cli, tmp_path, robot, log, *extra) -> dict:
    out = tmp_path / f"id-{log.parent.name}-{log.stem}.json"
    cli("identify", robot, log, "--method", "wls", "--json", out, *extra)
    res = json.loads(out.read_text())
    return dict(zip(res["parameters"]["names"], zip(res["parameters"]["values"], res["parameters"]["std"])))


def _fleet_json(cli, tmp_path, robot, root, *extra) -> dict:
    out = tmp_path / "fleet.json"
    cli("fleet", robot, root, "--by", BY, "--scheduler", "threads:2", "--json", out, *extra)
    return json.loads(out.read_text())


def _max_z(fleet_day: dict, ident: dict) -> float:
    """Largest |fleet - identify| in identify's standard deviations, over every parameter."""
    assert set(fleet_day["names"]) == set(ident)
    return max(abs(v - ident[n][0]) / ident[n][1] for n, v in zip(fleet_day["names"], fleet_day["values"]))


def _truth_z(names, values, std, truth: np.ndarray) -> np.ndarray:
    return (np.asarray(values) - truth) / np.asarray(std)


def _check_truth(z: np.ndarray, what: str) -> None:
    """Simulated truth recovered within the estimate's own uncertainty: at most 2 % of the standardised errors
    beyond 3 sigma (0.27 % for exact sigmas), none beyond 5, and a root-mean-square below 1.5. IDIM-WLS's
    sigmas ignore the position noise in the regressor (errors in variables): with 1e-5 rad on q the
    root-mean-square is 1.15-1.21 at 100 Hz-1 kHz (0.84-0.91 without that noise; 8 seeds, 8-s LWR4 logs)."""
    z = np.asarray(z, float).ravel()
    rms = float(np.sqrt(np.mean(z ** 2)))
    assert rms <= 1.5 and np.abs(z).max() <= 5.0, f"{what}: rms z {rms:.2f}, max {np.abs(z).max():.2f}"
    assert np.mean(np.abs(z) > 3) <= 0.02, f"{what}: {np.sum(np.abs(z) > 3)} of {z.size} beyond 3 sigma"


@pytest.mark.parametrize(("fs", "extra"), [
    (100.0, ()), (250.0, ()), (500.0, ()), (1000.0, ()),
    # the rule's edges: a cut-off given without n_d, n_d given without a cut-off, n_d = 1 (no decimation:
    # the assembly's path, not the fused kernel), and blocks of the zero-phase filter inside one log
    (500.0, ("--cutoff", "25")), (500.0, ("--decimate", "12")), (250.0, ("--decimate", "1")),
    (1000.0, ("--chunk-samples", "3000")),
])
def test_per_day_estimates_are_identifys_and_recover_the_truth(cli, tmp_path, fs, extra):
    truth = simulate_fleet(tmp_path / "logs", "lwr4", n_robots=2, n_days=1, duration=8.0, fs=fs, drifts=(),
                           seed=int(fs) + len(extra))
    _, model = model_for("lwr4")
    fleet = _fleet_json(cli, tmp_path, "lwr4", tmp_path / "logs", *extra)
    id_extra = () if extra[:1] == ("--chunk-samples",) else extra   # identify has no blocks: one filter pass
    zs = []
    for r in truth.robots:
        day = fleet["robots"][r]["days"]["d00"]
        ident = _identify(cli, tmp_path, "lwr4", truth.root / r / "d00.parquet", *id_extra)
        assert _max_z(day, ident) <= 0.1, (r, fs, extra)
        zs.append(_truth_z(day["names"], day["values"], day["std"], model.base_parameters(truth.chi[r])))
    _check_truth(np.concatenate(zs), f"{fs:g} Hz {' '.join(extra)}")


def test_fleet_and_identify_use_the_same_robot_file(cli, tmp_path, monkeypatch):
    """``generated/scara/`` written from a robot file whose D2 differs from ``robots/scara.toml``: identify reads
    the robot file; so must the fleet and ``load_model("scara")``."""
    gen = tmp_path / "generated"
    other = tmp_path / "other" / "scara.toml"
    other.parent.mkdir()
    text = (robots_dir() / "scara.toml").read_text()
    changed = text.replace("D2 = 0.35", "D2 = 0.99")
    assert changed != text
    other.write_text(changed)
    cli("generate", other, "--out", gen)
    monkeypatch.setenv("SYMORO_GENERATED", str(gen))
    m_other = load_model(str(gen / "scara"))
    m_name = load_model("scara")
    _, m_file = model_for("scara")
    q = np.random.default_rng(0).uniform(-1, 1, (5, 4))
    assert np.array_equal(m_name.regressor(q, q, q), m_file.regressor(q, q, q))
    assert not np.allclose(m_other.regressor(q, q, q), m_file.regressor(q, q, q))
    truth = simulate_fleet(tmp_path / "logs", "scara", n_robots=2, n_days=2, duration=4.0, drifts=(), seed=7)
    fleet = _fleet_json(cli, tmp_path, "scara", tmp_path / "logs")
    for r in truth.robots:
        for d in truth.days:
            ident = _identify(cli, tmp_path, "scara", truth.root / r / f"{d}.parquet")
            assert _max_z(fleet["robots"][r]["days"][d], ident) <= 0.1, (r, d)


def test_the_drifting_unit_of_an_lwr4_fleet_is_flagged(tmp_path, threads_client):
    """Four LWR4 units x four days of 20 s at 500 Hz, one unit's joint-2 viscous friction growing 25 % a day."""
    truth = simulate_fleet(tmp_path, "lwr4", n_robots=4, n_days=4, duration=20.0, fs=500.0,
                           drifts=(Drift("r01", "FV2", 0.25),), seed=0)
    res = identify_fleet("lwr4", [tmp_path], BY, client=threads_client)
    assert {f["robot"] for f in res.flagged} == {"r01"}, res.summary()
    assert "FV2" in [f["parameter"] for f in res.flagged if f["robot"] == "r01"]
    _, model = model_for("lwr4")
    k = res.names.index("FV2")
    base = np.array(truth.standard_names) == "FV2"
    for i, d in enumerate(truth.days):
        chi = truth.chi["r01"].copy()
        chi[base] *= 1.0 + 0.25 * i
        est = res.days["r01"][d]
        assert abs(est.values[k] - model.base_parameters(chi)[k]) <= 3 * est.std[k], d


@pytest.mark.slow
def test_no_unit_flagged_in_twenty_clean_fleets(tmp_path, threads_client):
    """No drift, per-unit scatter of a few %: twenty fleets of 4 units x 4 days, none flagged (Holm, 1 %)."""
    flagged = []
    for seed in range(20):
        root = tmp_path / f"f{seed}"
        simulate_fleet(root, "scara", n_robots=4, n_days=4, duration=5.0, drifts=(), seed=1000 + seed)
        res = identify_fleet("scara", [root], BY, client=threads_client)
        flagged += [(seed, f["robot"], f["parameter"]) for f in res.flagged]
        shutil.rmtree(root)
    assert flagged == []
