"""The JSON schemas of docs/schemas/ against real outputs of `identify` and `diagnose` (simulated
data), and the validator against outputs that break the contract."""
import copy
import json

import numpy as np
import pytest

from symoro_gen.description import load_robot
from symoro_gen.description.identity import robot_id
from symoro_gen.simulate import write_recording_csv

from .jsonschema_lite import KEYWORDS, validate
from .runner import DOCS, strict_json

SCHEMAS = {name: json.loads((DOCS / "schemas" / f"{name}.schema.json").read_text()) for name in ("identify", "diagnose")}


def _subschemas(s):
    """Every schema nested in ``s`` (to check the keywords used)."""
    yield s
    for k, v in s.items():
        if k in ("properties", "$defs"):
            for sub in v.values():
                yield from _subschemas(sub)
        elif k in ("items", "additionalProperties") and isinstance(v, dict):
            yield from _subschemas(v)
        elif k in ("anyOf", "allOf"):
            for sub in v:
                yield from _subschemas(sub)


@pytest.mark.parametrize("name", sorted(SCHEMAS))
def test_schema_well_formed(name):
    s = SCHEMAS[name]
    assert s["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    for sub in _subschemas(s):
        assert set(sub) <= KEYWORDS, set(sub) - KEYWORDS
        if "required" in sub:
            assert set(sub["required"]) <= set(sub.get("properties", {})), sub["required"]
        ref = sub.get("$ref")
        if ref:
            assert ref.split("/")[-1] in s["$defs"]
    try:  # cross-check with the reference implementation when it is installed
        import jsonschema
    except ImportError:
        return
    jsonschema.Draft202012Validator.check_schema(s)


def check(instance, name):
    errs = validate(instance, SCHEMAS[name])
    assert not errs, "\n".join(errs[:20])
    try:
        import jsonschema
    except ImportError:
        return
    jsonschema.validate(instance, SCHEMAS[name])


@pytest.fixture(scope="module")
def scara_files(tmp_path_factory):
    from symoro_gen.loader import model_for
    from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, simulate_recording

    rng = np.random.default_rng(5)
    robot, model = model_for("scara")
    chi = np.asarray(random_physical_parameters(robot, rng))
    d = tmp_path_factory.mktemp("scara")
    files = []
    for k in range(2):
        t, q, dq, ddq = fourier_trajectory(robot.n_joints, 8.0, 0.002, rng)
        tr = simulate_recording(model, t, q, dq, ddq, chi, noise_q=1e-5, noise_tau=0.01, rng=rng)
        write_recording_csv(d / f"rec{k}.csv", tr)
        files.append(str(d / f"rec{k}.csv"))
    return d, files


def test_identify_output_matches_schema(scara_files, cli):
    d, files = scara_files
    out = d / "r.json"
    cli("--quiet", "identify", "scara", files[0], "--validate", files[1], "--method", "ols", "--json", out, rc=0)
    res = strict_json(out)
    check(res, "identify")
    p = res["parameters"]
    assert len(p["names"]) == len(p["values"]) == len(p["std"]) == len(p["rel_std_pct"])
    assert len(res["rel_err"]) == len(res["validation"]["rel_err"]) == 4
    assert len(res["rel_err_raw"]) == len(res["validation"]["rel_err_raw"]) == 4
    assert res["rel_err_basis"]["n_d"] and res["validation"]["rel_err_basis"]["samples"] > 0


def test_identify_with_gains_matches_schema(tmp_path, cli):
    """LWR4 torque-sensor gains with a known payload mass (the demo's job through the command)."""
    from symoro_gen.demo import TRUE_GAINS, demo_payload
    from symoro_gen.loader import model_for
    from symoro_gen.simulate import fourier_trajectory, simulate_recording

    rng = np.random.default_rng(0)
    robot, model = model_for("lwr4")
    chi = model.nominal_parameters()
    files = {}
    for kind, pay in (("unloaded", None), ("loaded", demo_payload())):
        t, q, dq, ddq = fourier_trajectory(robot.n_joints, 10.0, 0.005, rng, vmax=1.5, amax=6.0)
        tr = simulate_recording(model, t, q, dq, ddq, chi, chi_payload=pay, gains=TRUE_GAINS, noise_q=2e-5,
                                noise_tau=0.02, rng=rng)
        files[kind] = tmp_path / f"{kind}.npz"
        np.savez(files[kind], t=tr.t, q=tr.q, tau=tr.tau)
    out = tmp_path / "g.json"
    cli("--quiet", "identify", "lwr4", files["unloaded"], "--loaded", files["loaded"], "--payload", "M8=4.6136",
        "--gains", "sensor", "--json", out, rc=0)
    res = strict_json(out)
    check(res, "identify")
    g = res["gains"]
    assert g["joints"] == list(range(1, 8)) and np.allclose(g["values"], TRUE_GAINS, rtol=0.01)


@pytest.fixture(scope="module")
def diagnose_report():
    """A diagnosis of simulated data with a Stribeck effect injected on joint 1."""
    from symoro_gen.diagnostics import DiagnoseSettings, diagnose, inject_effect
    from symoro_gen.loader import model_for
    from symoro_gen.preprocessing.trajectory import Trajectory
    from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, true_torques

    rng = np.random.default_rng(2)
    robot, model = model_for("scara")
    chi = np.asarray(random_physical_parameters(robot, rng))
    trs = []
    for k in range(2):
        t, q, dq, ddq = fourier_trajectory(robot.n_joints, 20.0, 0.002, rng)
        tau = true_torques(model, q, dq, ddq, chi)
        qm, taum = inject_effect("stribeck", t, q, dq, ddq, tau, joint=0, Fst=2.0, vs=0.1)
        trs.append(Trajectory(t=t, q=qm + 1e-5 * rng.standard_normal(qm.shape),
                              tau=taum + 0.01 * rng.standard_normal(taum.shape), source=f"sim{k}"))
    return diagnose(model, trs[:1], DiagnoseSettings(method="ols"), validation=trs[1:])


def test_diagnose_output_matches_schema(diagnose_report):
    d = json.loads(json.dumps(diagnose_report.to_dict(), allow_nan=False))
    check(d, "diagnose")
    assert d["effects"], "the injected Stribeck friction should be found"
    first = d["effects"][0]
    # found either by the friction-law stage (a Stribeck law replacing Coulomb on joint 1) or by the loop
    assert first["joint"] == 1 and (first["kind"] == "stribeck" or (
        first["kind"] == "friction_law" and first.get("variant", "").startswith("stribeck"))), first
    assert len(d["before"]["rel_err"]) == len(d["after"]["validation_rel_err"]) == 4
    assert len(d["before"]["validation_rel_err_raw"]) == len(d["after"]["validation_rel_err_raw"]) == 4


def test_diagnose_cli_output_matches_schema(scara_files, cli):
    from .runner import available_commands

    if "diagnose" not in available_commands():
        pytest.skip("the diagnose command is not there yet")
    d, files = scara_files
    out = d / "diag.json"
    cli("--quiet", "diagnose", "scara", files[0], "--validate", files[1], "--json", out, rc=0)
    check(strict_json(out), "diagnose")
    doc = strict_json(out)
    keys = list(doc)
    assert keys[keys.index("robot") + 1] == "robot_id" and doc["robot_id"] == robot_id(load_robot("scara"))


# ---------------------------------------------------------------------------------------------
# the validator rejects outputs that break the contract
# ---------------------------------------------------------------------------------------------
GOOD_IDENTIFY = {"robot": "scara", "data": ["a.csv"], "method": "OLS",
                 "parameters": {"names": ["ZZ1R"], "values": [1.0], "std": [0.1], "rel_std_pct": [10.0]},
                 "rel_err": [0.1, 0.2], "rel_err_raw": [0.2, 0.3], "cond": 12.0, "sigma": 0.3}


@pytest.mark.parametrize("break_it, where", [
    (lambda d: d.pop("parameters"), "missing required key 'parameters'"),
    (lambda d: d["parameters"].pop("std"), "missing required key 'std'"),
    (lambda d: d.__setitem__("rel_err", [0.1, -0.2]), "$.rel_err[1]"),
    (lambda d: d.__setitem__("cond", "big"), "$.cond"),
    (lambda d: d["parameters"]["names"].__setitem__(0, 3), "$.parameters.names[0]"),
    (lambda d: d.__setitem__("gains", {"values": [1.0]}), "missing required key 'rel_std_pct'"),
    (lambda d: d.__setitem__("validation", {"rel_err": "0.1"}), "$.validation.rel_err"),
    (lambda d: d.pop("rel_err_raw"), "missing required key 'rel_err_raw'"),
    (lambda d: d.__setitem__("validation", {"rel_err": [0.1, 0.2]}), "missing required key 'rel_err_raw'"),
    (lambda d: d.__setitem__("rel_err_basis", {"rel_err": "x", "rel_err_raw": "y", "cutoff_hz": [0.0], "n_d": [1],
                                               "rows": 1, "samples": 1}), "$.rel_err_basis.cutoff_hz[0]"),
    (lambda d: d.__setitem__("robot_id", "scara"), "$.robot_id"),
    (lambda d: d.__setitem__("robot_id", "E4BBB72E57DF487C"), "$.robot_id"),
])
def test_validator_catches_broken_identify(break_it, where):
    assert validate(GOOD_IDENTIFY, SCHEMAS["identify"]) == []
    bad = copy.deepcopy(GOOD_IDENTIFY)
    break_it(bad)
    errs = validate(bad, SCHEMAS["identify"])
    assert any(where in e for e in errs), errs


def test_validator_catches_broken_diagnose():
    good = {"before": {"rel_err": [0.1], "validation_rel_err": [0.2], "validation_rel_err_raw": [0.3]},
            "after": {"rel_err": [0.05], "validation_rel_err": [0.1], "validation_rel_err_raw": [0.2]},
            "effects": [{"kind": "stribeck", "joint": 1, "params": {"FST1": 1.2}, "score": 0.3}],
            "tried": [{"kind": "spring", "joint": None, "score": 0.01}]}
    assert validate(good, SCHEMAS["diagnose"]) == []
    for mutate, where in (
        (lambda d: d["effects"][0].__setitem__("kind", "magic"), "not one of"),
        (lambda d: d["effects"][0].__setitem__("joint", 0), "$.effects[0].joint"),
        (lambda d: d["after"].pop("validation_rel_err"), "validation_rel_err"),
        (lambda d: d["before"].pop("validation_rel_err_raw"), "missing required key 'validation_rel_err_raw'"),
        (lambda d: d["tried"][0].pop("score"), "missing required key 'score'"),
    ):
        bad = copy.deepcopy(good)
        mutate(bad)
        errs = validate(bad, SCHEMAS["diagnose"])
        assert any(where in e for e in errs), (where, errs)


def test_strict_json_refuses_nan(tmp_path):
    f = tmp_path / "x.json"
    f.write_text('{"cond": NaN}')
    with pytest.raises(ValueError, match="not valid JSON"):
        strict_json(f)
