"""identify --physical and standard_from_base on simulated arms with known truth."""
import json

import numpy as np
import pytest

pytest.importorskip("cvxpy", reason="the 'physical' extra (cvxpy, clarabel) is not installed")

from symoro_gen.description.inertia import check_physical_consistency
from symoro_gen.identification import identify, stack_systems
from symoro_gen.identification.physical import (
    base_matrix,
    identify_physical,
    standard_from_base,
)
from symoro_gen.identification.result import per_joint_rel_err
from symoro_gen.loader import model_for
from symoro_gen.observations.assembly import assemble
from symoro_gen.observations.options import AssemblyOptions
from symoro_gen.params import INERTIAL_KINDS
from symoro_gen.simulate import (
    fourier_trajectory,
    random_payload,
    random_physical_parameters,
    simulate_recording,
    write_recording_csv,
)


@pytest.fixture(scope="module")
def rx90():
    return model_for("rx90")


def _bodies(names, values):
    d = dict(zip(names, values))
    frames = sorted({int(n[1:]) for n in names if n.startswith("M") and n[1:].isdigit()})
    return {j: [d[f"{k}{j}"] for k in INERTIAL_KINDS] for j in frames}


def _system(model, rng, truth, duration, *, harmonics=5, amplitude=1.0, vmax=2.0, noise=0.05, payload=None):
    n = model.N_JOINTS
    mo = fourier_trajectory(n, duration, 0.001, rng, n_harmonics=harmonics, amplitude=amplitude, vmax=vmax)
    rec = simulate_recording(model, mo.t, mo.q, mo.dq, mo.ddq, truth, chi_payload=payload, noise_tau=noise, rng=rng)
    return rec, assemble(model, rec, AssemblyOptions(payload_columns=payload is not None)).system


def _rel_err(system, pm):
    th = np.array([pm[n] for n in system.names])
    return per_joint_rel_err(system.Y - system.W @ th, system.Y, system.joint, system.n_joints)


def test_base_matrix_is_the_regrouping(rx90):
    _, model = rx90
    x = np.random.default_rng(0).normal(size=len(model.STANDARD_NAMES))
    assert np.allclose(base_matrix(model) @ x, model.base_parameters(x), rtol=1e-12, atol=1e-12)


def test_rich_data_physical_truth_is_recovered(rx90):
    """Truth physical and well excited: the constraints cost nothing and the base estimate is the
    unconstrained one (= the truth within noise); every body is consistent."""
    robot, model = rx90
    rng = np.random.default_rng(1)
    truth = np.asarray(random_physical_parameters(robot, rng))
    _, system = _system(model, rng, truth, 20.0)
    res = identify(system, method="ols")
    ph = identify_physical(model, system, nominal=dict(zip(robot.standard_names, robot.nominal_vector())))
    for j, p10 in _bodies(ph.names, ph.values).items():
        assert check_physical_consistency(p10) == [], f"link {j}"
    assert all(ph.values[ph.names.index(f"{k}{j}")] >= 0 for k in ("IA", "FV", "FS") for j in range(1, 7))
    assert ph.residual_increase_pct < 1e-3
    unc = np.array([ph.unconstrained[n] for n in model.BASE_NAMES])
    assert np.allclose(unc, res.values, rtol=1e-8, atol=1e-10)
    tb = model.base_parameters(truth)
    # consistent estimate = unconstrained estimate, to well below its standard deviation
    assert np.all(np.abs(ph.base_values - unc) <= 0.05 * res.std + 1e-9)
    # and both within 4 sigma of the truth
    assert np.all(np.abs(ph.base_values - tb) <= 4 * res.std + 1e-6)
    assert not any("set by the data" in a for a in ph.active_constraints)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_poor_data_physical_validates_better(rx90, seed):
    """3 s of small, slow motion with noisy torques: the unconstrained fit is not physical and
    extrapolates badly; the consistent one validates better on a rich trajectory."""
    robot, model = rx90
    rng = np.random.default_rng(seed)
    truth = np.asarray(random_physical_parameters(robot, rng))
    _, poor = _system(model, rng, truth, 3.0, harmonics=2, amplitude=0.3, vmax=0.8, noise=1.0)
    _, valid = _system(model, rng, truth, 20.0, noise=0.0)
    ph = identify_physical(model, poor)
    assert any("set by the data" in a for a in ph.active_constraints)
    assert ph.residual_increase_pct > 0
    e_u, e_p = _rel_err(valid, ph.unconstrained), _rel_err(valid, ph.parameter_map())
    assert np.mean(e_p) < 0.5 * np.mean(e_u), (e_p, e_u)
    for j, p10 in _bodies(ph.names, ph.values).items():
        assert check_physical_consistency(p10) == [], f"link {j}"


def test_known_payload_mass_and_consistent_payload(rx90):
    robot, model = rx90
    rng = np.random.default_rng(3)
    truth = np.asarray(random_physical_parameters(robot, rng))
    pay = np.asarray(random_payload(rng, robot=robot))
    _, su = _system(model, rng, truth, 10.0)
    _, sl = _system(model, rng, truth, 10.0, payload=pay)
    mname = model.PAYLOAD_NAMES[-1]
    ph = identify_physical(model, stack_systems(su, sl), known={mname: pay[-1]})
    assert ph.payload_names == tuple(model.PAYLOAD_NAMES)
    pv = np.asarray(ph.payload_values)
    assert pv[-1] == pay[-1]
    assert check_physical_consistency(pv) == []
    # first moments of the payload are identifiable: recovered
    assert np.allclose(pv[6:9], pay[6:9], atol=0.02 * np.abs(pay[6:9]).max())


def test_standard_from_base_exact_and_infeasible(rx90):
    robot, model = rx90
    rng = np.random.default_rng(4)
    truth = np.asarray(random_physical_parameters(robot, rng))
    chi_b = model.base_parameters(truth)
    sb = standard_from_base(model, chi_b, None)
    assert sb.exact and sb.notes == ()
    assert np.allclose(model.base_parameters(np.asarray(sb.values)), chi_b, rtol=1e-6, atol=1e-8 * np.abs(chi_b).max())
    for j, p10 in _bodies(sb.names, sb.values).items():
        assert check_physical_consistency(p10) == [], f"link {j}"
    # a negative viscous friction (never regrouped) cannot come from a physical robot
    bad = np.array(chi_b)
    bad[model.BASE_NAMES.index("FV2")] = -1.0
    sb2 = standard_from_base(model, bad, None)
    assert not sb2.exact and "no physically consistent" in sb2.notes[0]
    assert sb2.values[sb2.names.index("FV2")] == pytest.approx(0.0, abs=1e-6)


def test_cli_physical_json_contract(rx90, tmp_path, cli):
    robot, model = rx90
    rng = np.random.default_rng(5)
    truth = np.asarray(random_physical_parameters(robot, rng))
    rec, _ = _system(model, rng, truth, 4.0, harmonics=2, amplitude=0.4, vmax=1.0, noise=0.5)
    write_recording_csv(tmp_path / "poor.csv", rec)
    rec_v, _ = _system(model, rng, truth, 10.0, noise=0.0)
    write_recording_csv(tmp_path / "valid.csv", rec_v)
    out = tmp_path / "r.json"
    r = cli("identify", "rx90", tmp_path / "poor.csv", "--validate", tmp_path / "valid.csv", "--physical",
            "--json", out)
    assert "Cost of consistency" in r.out and "Active constraints" in r.out
    d = json.loads(out.read_text())
    ph = d["physical"]
    assert ph["names"] == list(model.STANDARD_NAMES)
    assert {"values", "active_constraints"} <= set(ph)
    implied = model.base_parameters(np.array(ph["values"]))
    pm = dict(zip(d["parameters"]["names"], d["parameters"]["values"]))
    assert np.allclose([pm[n] for n in model.BASE_NAMES], implied, rtol=1e-9, atol=1e-12)
    assert d["unconstrained"]["parameters"]["names"] == d["parameters"]["names"]
    assert np.mean(d["validation"]["rel_err"]) < np.mean(d["unconstrained"]["validation"]["rel_err"])
    for j, p10 in _bodies(ph["names"], ph["values"]).items():
        assert check_physical_consistency(p10) == [], f"link {j}"


def test_nominal_tolerance_needs_physical(cli, tmp_path):
    r = cli("identify", "rx90", "q=a.csv,tau=b.csv,dt=0.001", "--nominal-tolerance", "0.2", rc=None)
    assert r.rc != 0 and "--physical" in r.err


@pytest.mark.slow
@pytest.mark.realdata
def test_lwr4_real_recordings_physical(shared_data, tmp_path, cli):
    """LWR4 files 1+3, validated on 2: consistent bodies; the cost of consistency stays moderate."""
    D = shared_data / "kuka_lwr4_flobaroid" / "data" / "KUKA" / "HW"
    out = tmp_path / "lwr4.json"
    cli("identify", "lwr4", D / "measurements_1.npz", D / "measurements_3.npz", "--validate", D / "measurements_2.npz",
        "--method", "wls", "--physical", "--json", out, "-q")
    d = json.loads(out.read_text())
    ph = d["physical"]
    for j, p10 in _bodies(ph["names"], ph["values"]).items():
        assert check_physical_consistency(p10) == [], f"link {j}"
    assert 0 <= ph["residual_increase_pct"] < 100
    assert np.all(np.array(d["validation"]["rel_err"]) < 1.5 * np.array(d["unconstrained"]["validation"]["rel_err"]))
